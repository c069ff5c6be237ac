"""Layer 1: the freeform pixel.

Camera and detector layout, mask plane, detector electronics, closed-form
radiometry.
"""
