"""Layer 2: light transport.

The Mitsuba variant, scene building, transport images, estimators (differential,
sun patch, portal sky), fidelity planning, storage precision.
"""
