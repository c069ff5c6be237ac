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
- :mod:`.result` -- the typed result (:class:`Sim2RealResult`) and its records;
- :mod:`.study` -- :func:`analyze_sim2real`, all of the above for one recording;
- :mod:`.figures` and :mod:`.report` -- :func:`write_sim2real_report` writes
  ``sim2real.html`` and ``sim2real.json``.

Arrays are numpy (float64 for analysis) unless a docstring says torch; voltages
in volts, powers in watts. Importing this package imports numpy and scipy, not
torch or Mitsuba.
"""

from mincam_render.studies.sim2real.fit import THRESHOLDS, fit_gain_offset, injected_comparison
from mincam_render.studies.sim2real.recording import Sim2RealError, load_recording
from mincam_render.studies.sim2real.report import write_sim2real_report
from mincam_render.studies.sim2real.result import (
    GainOffsetFit,
    PixelVerdict,
    Sim2RealResult,
    Thresholds,
)
from mincam_render.studies.sim2real.study import analyze_sim2real
from mincam_render.studies.sim2real.surrogate import SurrogatePerturbations, make_surrogate

__all__ = [
    "THRESHOLDS",
    "GainOffsetFit",
    "PixelVerdict",
    "Sim2RealError",
    "Sim2RealResult",
    "SurrogatePerturbations",
    "Thresholds",
    "analyze_sim2real",
    "fit_gain_offset",
    "injected_comparison",
    "load_recording",
    "make_surrogate",
    "write_sim2real_report",
]
