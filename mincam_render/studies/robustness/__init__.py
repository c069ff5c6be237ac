"""A trained design under fabrication and detector perturbations: error, tolerance, spec."""
