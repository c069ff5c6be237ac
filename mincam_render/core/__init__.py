"""Layer 0: what every layer shares.

Typed configuration (TOML -> frozen dataclasses), photometric units, label
specifications, seeds.
"""
