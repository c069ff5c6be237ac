"""Layer 8: the ``mincam-render`` command line."""
