"""Example of a scene family in its own package: occupied parking spaces seen from a pole."""
