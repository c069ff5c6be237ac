"""Layer 7: studies and reports.

Fidelity bench, sim2real, previews, plots, HTML reports.
"""
