"""The fidelity benchmark: error against run time of every rendering knob."""
