"""Simulation against reality: compare rendered freeform-pixel measurements with a recording.

- :mod:`.recording` -- the **input format** of a recording (documented in
  ``docs/sim2real_format.md``): :func:`load_recording` reads and validates it;
- :mod:`.surrogate` -- a **SURROGATE-real generator**, :func:`make_surrogate`, for
  tests and demos (no prototype data exist here): a family rendered through a
  camera perturbed the way hardware deviates from its design, every injected
  value recorded in ``injected.json``, labelled SURROGATE in the files and in
  every report made from it;
- :mod:`.simulation` -- the recording's scene twin rendered to noiseless voltages;
- :mod:`.fit` -- per pixel the fitted gain and offset (``real = gain * sim +
  offset``, least squares with standard errors), correlation, residuals, the
  distribution gap (KS statistic and 1-Wasserstein distance, raw and after the
  fit) and the verdict against :data:`THRESHOLDS`;
- :mod:`.tasks` -- task metrics (trained on simulation / tested on real;
  sim-trained head retrained on real, as the paper did; trained and tested on real);
- :mod:`.config` -- :class:`Sim2RealConfig`, the comparison as data (a recording
  or a family to make a SURROGATE of, samples, steps, seed);
- :mod:`.result` -- the typed result (:class:`Sim2RealResult`) and its records;
- :mod:`.study` -- :func:`run`, all of the above for one recording;
- :mod:`.figures` and :mod:`.report` -- :func:`write_report` writes
  ``sim2real.html`` and ``sim2real.json``.

The study's shape is every study's: ``run(config, out)`` -> a frozen
:class:`Sim2RealResult` -> ``write_report(result, out)``.

Arrays are numpy (float64 for analysis) unless a docstring says torch; voltages
in volts, powers in watts. Importing this package imports numpy and scipy, not
torch or Mitsuba.
"""

from mincam_render.studies.sim2real.config import Sim2RealConfig
from mincam_render.studies.sim2real.fit import THRESHOLDS, fit_gain_offset, injected_comparison
from mincam_render.studies.sim2real.recording import Sim2RealError, load_recording
from mincam_render.studies.sim2real.report import write_report
from mincam_render.studies.sim2real.result import (
    GainOffsetFit,
    PixelVerdict,
    Sim2RealResult,
    Thresholds,
)
from mincam_render.studies.sim2real.study import run
from mincam_render.studies.sim2real.surrogate import SurrogatePerturbations, make_surrogate

__all__ = [
    "THRESHOLDS",
    "GainOffsetFit",
    "PixelVerdict",
    "Sim2RealConfig",
    "Sim2RealError",
    "Sim2RealResult",
    "SurrogatePerturbations",
    "Thresholds",
    "fit_gain_offset",
    "injected_comparison",
    "load_recording",
    "make_surrogate",
    "run",
    "write_report",
]
