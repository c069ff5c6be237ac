"""Studies: each a frozen configuration, a ``run`` entry, a typed result and its report.

The layer above :mod:`mincam_render.analysis` (statistics, reports, plots),
below the command line. A study imports no other study but the comparison
(:mod:`mincam_render.studies.comparison`), which the others build on.
"""
