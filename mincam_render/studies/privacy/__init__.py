"""Privacy audit: what can an attacker recover from a design's K measurements?

One concept a module, each importing only those before it: ``config`` (the
episodes, designs and attacker, as data), ``identities`` (who is where, from
the frames' scene states), ``metrics`` (display images, the foreground mask,
PSNR/SSIM via scikit-image, re-identification top-1), ``attacks`` (the trained
design's read-out, the training loop and the re-identifier; torch),
``decoders`` (MLP, convolutional and ridge decoders of what the people add to
the view; torch), ``result`` (the typed :class:`PrivacyResult`, ``privacy.json``), ``curve``
(which designs sit in the private, useful corner), ``study`` (:func:`run`),
``figures`` and ``report`` (:func:`write_report`). Importing
this package loads numpy, not torch or Mitsuba.
"""

from mincam_render.studies.privacy.config import AttackConfig, PrivacyConfig, default_comparison
from mincam_render.studies.privacy.curve import corner_verdicts
from mincam_render.studies.privacy.identities import presence
from mincam_render.studies.privacy.metrics import (
    foreground_mask,
    foreground_quality,
    reconstruction_quality,
    reid_top1,
)
from mincam_render.studies.privacy.report import headline, write_report
from mincam_render.studies.privacy.result import PrivacyResult
from mincam_render.studies.privacy.study import run

__all__ = [
    "AttackConfig",
    "PrivacyConfig",
    "PrivacyResult",
    "corner_verdicts",
    "default_comparison",
    "foreground_mask",
    "foreground_quality",
    "headline",
    "presence",
    "reconstruction_quality",
    "reid_top1",
    "run",
    "write_report",
]
