"""Studies: each a frozen configuration, ``run(config, out)``, a typed result and its report.

The layer above :mod:`mincam_render.analysis` (comparisons, statistics, plots),
below the command line.
"""
