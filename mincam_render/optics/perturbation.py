r"""How a built camera differs from its design: the one model of fabrication and mounting error.

A mask is printed on transparency film, cut, glued in front of a photodiode and
the board is screwed to a wall. :class:`PerturbationModel` gives each step's
error a physical unit and a default half-range; :meth:`PerturbationModel.draw`
samples one built camera (:class:`PerturbationDraw`). Every term is drawn
uniformly in ``[-a, a]`` (``[0, a]`` for the blur), so a default range reads
directly as a fabrication tolerance ("align masks to +-0.3 mm").

This is the one model of a built camera's deviations: robust training
(``TrainConfig.perturbation``), the robustness report
(:mod:`mincam_render.studies.robustness`) and the SURROGATE-real recordings of
the sim-to-real study (:mod:`mincam_render.studies.sim2real.surrogate`) all
draw from it, and the masks as built are made by one mask plane
(:mod:`mincam_render.optics.fabrication`; the fused copy training uses,
:mod:`mincam_render.optics.fabrication_fused`).

**Units.** Inside the package every field is SI: lengths in metres (``_m``),
angles in radians (``_rad``), the gain error a fraction (0.05 = 5 %),
voltages in volts; tone and printable-range terms are dimensionless. Files
(run records, robustness reports, ``injected.json``) and the command line keep
the workshop's units, converted once by :meth:`PerturbationModel.to_record` and
:meth:`PerturbationModel.from_record` with the named constants :data:`MM`,
:data:`CM`, :data:`DEG` and :data:`PERCENT` (:data:`RECORD_UNITS`):

============================  =========================  ==========
field (SI)                    record / CLI name          record unit
============================  =========================  ==========
``mask_shift_m``              ``mask_shift_mm``          mm
``mask_rotation_rad``         ``mask_rotation_deg``      deg
``mask_blur_m``               ``mask_blur_mm``           mm
``gain_mismatch_fraction``    ``gain_mismatch_percent``  %
``pose_orientation_rad``      ``pose_orientation_deg``   deg
``pose_position_m``           ``pose_position_cm``       cm
(the others)                  (the same name)            (the same)
============================  =========================  ==========

**What the two former models became.** Until issue 41 the sim-to-real
SURROGATE had its own ``SurrogatePerturbations`` with other physics. Its
parameters map onto this model as follows (``sqrt(3) sigma`` is the half-range
of a uniform draw with the old normal draw's standard deviation):

* ``mask_shift_m`` (normal sigma, m) -> ``mask_shift_m = sqrt(3) sigma``.
* ``mask_rotation_deg`` (normal sigma, deg) -> ``mask_rotation_rad = sqrt(3) sigma DEG``.
* ``printer_gamma`` (one fixed exponent ``g`` on the design's place in the
  printable range, the same curve as here) -> ``gamma_deviation = |g - 1|``
  (gamma now drawn in ``1 +- |g - 1|``).
* ``dot_gain`` ``d`` (transmittance times ``1 - d`` everywhere and a blur of
  ``10 d`` texels sigma) -> ``dot_gain_deviation = d``, and the uniform
  darkening becomes the printable range's errors
  ``min_transmittance_error = d lo``, ``max_transmittance_error = d hi``, the
  blur ``mask_blur_m``. The dot gain of this model is the better physics and
  the one kept: dot gain is a *tone value increase*, zero on bare film and
  on full ink and largest at mid-tones (``c -> c + 4 g c (1 - c)``, the
  printers' convention of quoting it at 50 % coverage, ISO 12647), while the old
  definition darkened the clear film as much as the mid-tones and tied the blur
  to the dot gain in texels, so the same print blurred more on a finer mask.
  The print's blur is a length of the print (``mask_blur_m``), whatever the texel.
* ``gain_sigma`` (normal, fraction) -> ``gain_mismatch_fraction = sqrt(3) sigma``;
  ``offset_sigma_v`` -> ``dark_offset_v = sqrt(3) sigma``. Both now act where
  this model puts them: the gain on each detector's power, the offset on its voltage.
* ``board_position_m`` (normal sigma per axis, m) ->
  ``pose_position_m = sqrt(3) sigma``; ``board_rotation_deg`` (normal sigma
  about up, then right) -> ``pose_orientation_rad = sqrt(3) sigma DEG`` about
  pan, tilt and roll (a roll error, which the old model lacked, included). The
  SURROGATE renders the moved camera (:func:`mincam_render.optics.pose.posed_camera`);
  training and the report approximate it in the mask plane.
* ``stray_light_fraction``, ``dark_current_a``, ``read_noise`` and
  ``common_random_numbers`` are no fabrication error: they stay settings of
  the SURROGATE (light and electronics the simulation leaves out).

Robust training's and the robustness report's old fields map one to one
(``mask_shift_mm`` -> ``mask_shift_m = mask_shift_mm MM`` and so on, the table
above); their files and options keep their names and units.

Defaults and their reasoning (``docs/robustness.md`` has the sources), in the
record's units:

* ``mask_shift_mm`` 0.3 mm per axis per detector: a film mask cut by hand and
  placed against a printed cut mark; 0.3 mm is the width of a scalpel cut and a
  pencil line, 0.6 texel of the prototype's 0.5-mm texels.
* ``mask_rotation_deg`` 2 deg per detector: a 16-mm square set by eye against
  a square mount moves its corner by 16 mm x tan(2 deg) = 0.56 mm.
* ``gamma_deviation`` 0.15: the printed tone curve ``y -> y^gamma`` (``y`` the
  design's place in the printable range) with ``gamma`` in ``1 +- 0.15``; an
  uncalibrated driver or another film batch changes mid-tones this much.
* ``dot_gain_deviation`` 0.1: ink coverage ``c -> c + 4 g c (1 - c)`` (dot gain
  ``g`` at 50 % coverage, the printers' convention); office laser and inkjet
  printers on film show 10-20 % dot gain, a calibration removes the mean, the
  spread remains.
* ``min_transmittance_error`` 0.005 and ``max_transmittance_error`` 0.05: the
  printable range 0.01-0.67 of the paper (supplement B) was measured on one
  printer and film; the film base and the darkest ink vary between batches.
* ``mask_blur_mm`` 0.1 mm: Gaussian sigma up to the spread of a 600-dpi dot
  (42 um) plus the film lying up to ~0.1 mm off the mask plane.
* ``gain_mismatch_percent`` 5 %: per-detector responsivity spread of one diode
  type plus 1 % transimpedance resistors.
* ``dark_offset_v`` 2 mV: the transimpedance amplifier's output offset (input
  offset voltage of a precision op-amp, ~1 mV, times its noise gain) plus dark
  current times the gain (``1e-11 A x 1e7 V/A = 0.1 mV``).
* ``pose_orientation_deg`` 2 deg per axis (pan, tilt, roll): a board screwed to
  a wall or bracket and aimed by eye; 1 mm of play in a screw hole 3 cm from the
  pivot turns it by 2 deg.
* ``pose_position_cm`` 2 cm per axis (right, up, forward): screw holes marked
  with a tape measure from a drawing of the room.
* ``pose_depth_m`` 4 m (a setting, not a half-range): the scene depth at which a
  position error is modelled exactly (:mod:`mincam_render.optics.pose`); the
  median depth of the workspace's view (3.8 m). Of planes at 1, 2 and 4 m, the
  4-m one came closest to re-renders (``benchmarks/bench_pose_error.py``); the
  nearest depth (0.8 m, the ceiling above the camera) came farthest.

The camera pose terms change the transport itself; they are approximated in
the mask plane (:mod:`mincam_render.optics.pose`: exact for rotations, for
offsets at ``pose_depth_m``), measured against re-renders by
``benchmarks/bench_pose_error.py``.

Arrays are numpy; the torch side (the fabricated mask plane) is
:mod:`mincam_render.optics.fabrication`.
"""

from __future__ import annotations

import enum
import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from mincam_render.core.checks import check_number
from mincam_render.optics.camera import MM

CM = 1e-2  #: metres per centimetre
DEG = math.pi / 180.0  #: radians per degree
PERCENT = 1e-2  #: fraction per percent


class PerturbationTerm(enum.Enum):
    """One source of error, possibly of several fields (see :data:`TERM_FIELDS`)."""

    MASK_SHIFT = "mask_shift"
    MASK_ROTATION = "mask_rotation"
    TONE = "tone"
    PRINTABLE_RANGE = "printable_range"
    MASK_BLUR = "mask_blur"
    GAIN_MISMATCH = "gain_mismatch"
    DARK_OFFSET = "dark_offset"
    POSE_ORIENTATION = "pose_orientation"
    POSE_POSITION = "pose_position"


#: The :class:`PerturbationModel` fields of each term.
TERM_FIELDS: dict[PerturbationTerm, tuple[str, ...]] = {
    PerturbationTerm.MASK_SHIFT: ("mask_shift_m",),
    PerturbationTerm.MASK_ROTATION: ("mask_rotation_rad",),
    PerturbationTerm.TONE: ("gamma_deviation", "dot_gain_deviation"),
    PerturbationTerm.PRINTABLE_RANGE: ("min_transmittance_error", "max_transmittance_error"),
    PerturbationTerm.MASK_BLUR: ("mask_blur_m",),
    PerturbationTerm.GAIN_MISMATCH: ("gain_mismatch_fraction",),
    PerturbationTerm.DARK_OFFSET: ("dark_offset_v",),
    PerturbationTerm.POSE_ORIENTATION: ("pose_orientation_rad",),
    PerturbationTerm.POSE_POSITION: ("pose_position_m",),
}
#: The half-ranges (every field of the model but the settings).
MAGNITUDES: tuple[str, ...] = tuple(f for fs in TERM_FIELDS.values() for f in fs)

#: Field -> (its name in records and on the command line, SI units per record unit,
#: record unit); fields not listed keep their name and unit.
RECORD_UNITS: dict[str, tuple[str, float, str]] = {
    "mask_shift_m": ("mask_shift_mm", MM, "mm"),
    "mask_rotation_rad": ("mask_rotation_deg", DEG, "deg"),
    "mask_blur_m": ("mask_blur_mm", MM, "mm"),
    "gain_mismatch_fraction": ("gain_mismatch_percent", PERCENT, "%"),
    "pose_orientation_rad": ("pose_orientation_deg", DEG, "deg"),
    "pose_position_m": ("pose_position_cm", CM, "cm"),
}

#: Record field -> (record unit, upper bound, whether the bound is open): the allowed
#: range ``[0, bound]`` (``(0, bound]`` for the settings, which are not half-ranges).
_RECORD_LIMITS: dict[str, tuple[str, float, bool]] = {
    "mask_shift_mm": ("mm", 16.0, False),
    "mask_rotation_deg": ("deg", 45.0, False),
    "gamma_deviation": ("", 1.0, True),
    "dot_gain_deviation": ("", 0.25, False),
    "min_transmittance_error": ("", 0.5, False),
    "max_transmittance_error": ("", 0.5, False),
    "mask_blur_mm": ("mm", 16.0, False),
    "gain_mismatch_percent": ("%", 100.0, True),
    "dark_offset_v": ("V", 10.0, False),
    # beyond ~30 deg a good part of the view is content no render holds
    "pose_orientation_deg": ("deg", 30.0, False),
    "pose_position_cm": ("cm", 100.0, False),
    "pose_depth_m": ("m", 1e4, False),
}


def record_name(name: str) -> str:
    """The record's (and the command line's) name of model field ``name``."""
    return RECORD_UNITS[name][0] if name in RECORD_UNITS else name


def _per_record_unit(name: str) -> float:
    """SI units per record unit of model field ``name`` (1 where the units agree)."""
    return RECORD_UNITS[name][1] if name in RECORD_UNITS else 1.0


def _si_limit(name: str) -> tuple[str, float, bool]:
    """``(unit, bound, open)`` of model field ``name`` in SI: the record's bound converted."""
    unit, bound, open_ = _RECORD_LIMITS[record_name(name)]
    si_unit = {"mm": "m", "cm": "m", "deg": "rad", "%": ""}.get(unit, unit)
    return si_unit, bound * _per_record_unit(name), open_


def _check_magnitude(owner: str, name: str, value: object, limit: tuple[str, float, bool]) -> float:
    """``value`` as a float in ``[0, bound]`` of ``limit``, else ValueError naming it."""
    unit, bound, open_ = limit
    setting = name == "pose_depth_m"
    return check_number(
        f"{owner}.{name}", value, 0, bound, unit=unit, lo_open=setting, hi_open=open_, numpy=True
    )


@dataclass(frozen=True, kw_only=True)
class PerturbationModel:
    """Half-ranges of the differences between a built camera and its design (SI; defaults above).

    Args:
        mask_shift_m: mask position error per axis per detector (m), [0, 0.016].
        mask_rotation_rad: mask rotation error per detector (rad), [0, pi/4].
        gamma_deviation: printed tone-curve exponent ``gamma = 1 +- a``, [0, 1).
        dot_gain_deviation: dot gain at 50 % ink coverage, ``+- a``, [0, 0.25]
            (the curve stays monotone up to 0.25).
        min_transmittance_error: error of the printable minimum transmittance, [0, 0.5].
        max_transmittance_error: error of the printable maximum transmittance, [0, 0.5].
        mask_blur_m: Gaussian blur sigma of the print, drawn in ``[0, a]`` (m), [0, 0.016].
        gain_mismatch_fraction: per-detector gain error (fraction, 0.05 = 5 %), [0, 1).
        dark_offset_v: per-detector output offset (V), [0, 10].
        pose_orientation_rad: camera orientation error per axis (pan, tilt,
            roll; rad), [0, pi/6].
        pose_position_m: camera position error per axis (right, up, forward;
            m), [0, 1].
        pose_depth_m: the depth at which a position error is modelled exactly
            (m), (0, 1e4]; a setting, not scaled with the half-ranges.

    Raises:
        ValueError: a field is negative, NaN, infinite or above its bound (the
            message names the field, its unit and the allowed range).

    """

    mask_shift_m: float = 0.3 * MM
    mask_rotation_rad: float = 2.0 * DEG
    gamma_deviation: float = 0.15
    dot_gain_deviation: float = 0.1
    min_transmittance_error: float = 0.005
    max_transmittance_error: float = 0.05
    mask_blur_m: float = 0.1 * MM
    gain_mismatch_fraction: float = 5.0 * PERCENT
    dark_offset_v: float = 2e-3
    pose_orientation_rad: float = 2.0 * DEG
    pose_position_m: float = 2.0 * CM
    pose_depth_m: float = 4.0

    def __post_init__(self) -> None:
        for f in fields(self):
            limit = _si_limit(f.name)
            value = _check_magnitude("PerturbationModel", f.name, getattr(self, f.name), limit)
            object.__setattr__(self, f.name, value)

    def to_record(self) -> dict[str, float]:
        """The model as files and the command line hold it: ``{record name: value}``.

        In the record's units (:data:`RECORD_UNITS`: mm, deg, %, cm), in field
        order; values rounded to 15 significant digits, so that the defaults read
        0.3 mm and 2 deg, not their binary neighbours.
        """
        return {
            record_name(f.name): float(f"{getattr(self, f.name) / _per_record_unit(f.name):.15g}")
            for f in fields(self)
        }

    @classmethod
    def from_record(cls, record: Mapping[str, Any]) -> PerturbationModel:
        """The model of a record (:meth:`to_record`'s form; missing names take their defaults).

        Raises:
            ValueError: an unknown name, or a value outside its range (the message
                names the record's field and unit, e.g. ``PerturbationModel.mask_shift_mm``).
        """
        names = {record_name(f.name): f.name for f in fields(cls)}
        unknown = sorted(set(record) - set(names))
        if unknown:
            raise ValueError(
                f"PerturbationModel: unknown field(s) {', '.join(unknown)}; allowed: "
                + ", ".join(names)
            )
        values = {}
        for key, value in record.items():
            checked = _check_magnitude("PerturbationModel", key, value, _RECORD_LIMITS[key])
            values[names[key]] = checked * _per_record_unit(names[key])
        return cls(**values)

    @classmethod
    def zero(cls) -> PerturbationModel:
        """The camera as designed: every term 0 (settings at their defaults)."""
        return cls(**dict.fromkeys(MAGNITUDES, 0.0))

    def only(self, term: PerturbationTerm) -> PerturbationModel:
        """This model with every term but ``term`` set to 0 (settings kept)."""
        keep = TERM_FIELDS[PerturbationTerm(term)]
        return replace(self, **{n: 0.0 for n in MAGNITUDES if n not in keep})

    def scaled(self, factor: float) -> PerturbationModel:
        """Every half-range times ``factor`` (>= 0; the result is validated; settings kept)."""
        if not (math.isfinite(factor) and factor >= 0):
            raise ValueError(f"factor = {factor!r} is invalid: allowed a finite number >= 0")
        return replace(self, **{n: getattr(self, n) * factor for n in MAGNITUDES})

    def is_zero(self) -> bool:
        """Whether every half-range is 0 (a draw is then the identity)."""
        return all(getattr(self, n) == 0.0 for n in MAGNITUDES)

    def draw(self, num_pixels: int, rng: np.random.Generator) -> PerturbationDraw:
        """One built camera of ``num_pixels`` freeform pixels (uniform draws of every term)."""
        return self.draw_from(rng.random(self.uniforms_needed(num_pixels)), num_pixels)

    @staticmethod
    def uniforms_needed(num_pixels: int) -> int:
        """How many U(0, 1) numbers :meth:`draw_from` takes for ``num_pixels`` pixels."""
        return 5 * int(num_pixels) + 11

    def draw_from(self, u: np.ndarray, num_pixels: int) -> PerturbationDraw:
        """The built camera of :meth:`uniforms_needed` uniforms ``u`` in [0, 1] (numpy).

        Training draws ``u`` from its torch generator (a resumed run draws the same).

        Raises:
            ValueError: ``num_pixels`` < 1, ``u`` of another length or outside [0, 1].
        """
        k = int(num_pixels)
        if k < 1:
            raise ValueError(f"num_pixels = {num_pixels!r}: need at least 1")
        u = np.asarray(u, np.float64)
        if u.shape != (self.uniforms_needed(k),):
            raise ValueError(f"u has shape {u.shape}: expected ({self.uniforms_needed(k)},)")
        if not ((u >= 0.0) & (u <= 1.0)).all():  # NaN fails both
            raise ValueError("u must be uniforms in [0, 1]")
        # U(-1, 1) times each number's half-range, in one product
        a = (2.0 * u - 1.0) * _half_ranges(self, k)
        gamma, dot, lo, hi = a[3 * k : 3 * k + 4].tolist()
        # valid by construction (a validated model, u in [0, 1]): the draw's own
        # checks would cost a quarter of a robust step's draw
        return _trusted_draw(
            shift_m=a[: 2 * k].reshape(k, 2),
            rotation_rad=a[2 * k : 3 * k],
            gamma=1.0 + gamma,
            dot_gain=dot,
            min_transmittance_error=lo,
            max_transmittance_error=hi,
            blur_sigma_m=self.mask_blur_m * float(u[3 * k + 4]),  # in [0, a]
            gain=1.0 + a[3 * k + 5 : 4 * k + 5],
            offset_v=a[4 * k + 5 : 5 * k + 5],
            pose_rotation_rad=a[5 * k + 5 : 5 * k + 8],
            pose_offset_m=a[5 * k + 8 :],
            pose_depth_m=self.pose_depth_m,
        )


@functools.lru_cache(maxsize=32)
def _half_ranges(model: PerturbationModel, k: int) -> np.ndarray:
    """Each uniform's half-range in :meth:`PerturbationModel.draw_from`'s order (read-only).

    The blur's place holds 0: it is drawn in ``[0, a]`` from its uniform directly.
    """
    m = model
    out = np.concatenate(
        [
            np.full(2 * k, m.mask_shift_m),
            np.full(k, m.mask_rotation_rad),
            [m.gamma_deviation, m.dot_gain_deviation],
            [m.min_transmittance_error, m.max_transmittance_error, 0.0],
            np.full(k, m.gain_mismatch_fraction),
            np.full(k, m.dark_offset_v),
            np.full(3, m.pose_orientation_rad),
            np.full(3, m.pose_position_m),
        ]
    )
    out.setflags(write=False)
    return out


def _vector(name: str, value: object, shape: tuple[int, ...]) -> np.ndarray:
    arr = np.array(value, dtype=np.float64)
    if arr.shape != shape or not np.isfinite(arr).all():
        raise ValueError(f"PerturbationDraw.{name} must be {shape} finite numbers; got {value!r}")
    return arr


@dataclass(frozen=True, kw_only=True)
class PerturbationDraw:
    """One built camera: the drawn value of every term (numpy SI, per pixel where it says so).

    Args:
        shift_m: ``[pixel, 2]`` mask displacement (m): rows (down), columns (right).
        rotation_rad: ``[pixel]`` mask rotation about its centre (rad), clockwise
            as seen from the camera (row 0 up).
        gamma: printed tone-curve exponent, > 0.
        dot_gain: dot gain at 50 % ink coverage, [-0.25, 0.25].
        min_transmittance_error: added to the printable minimum transmittance.
        max_transmittance_error: added to the printable maximum transmittance.
        blur_sigma_m: Gaussian blur sigma of the print (m), >= 0.
        gain: ``[pixel]`` factor on each detector's power, > 0.
        offset_v: ``[pixel]`` added to each detector's output voltage (V).
        pose_rotation_rad: camera ``(pan, tilt, roll)`` (rad): pan turns the view
            right, tilt up, roll clockwise as seen from the camera
            (:func:`mincam_render.optics.pose.pose_rotation`).
        pose_offset_m: camera displacement ``(right, up, forward)`` (m).
        pose_depth_m: depth at which the displacement is modelled exactly (m), > 0.

    """

    shift_m: np.ndarray
    rotation_rad: np.ndarray
    gamma: float = 1.0
    dot_gain: float = 0.0
    min_transmittance_error: float = 0.0
    max_transmittance_error: float = 0.0
    blur_sigma_m: float = 0.0
    gain: np.ndarray = field(default_factory=lambda: np.ones(0))
    offset_v: np.ndarray = field(default_factory=lambda: np.zeros(0))
    pose_rotation_rad: np.ndarray = field(default_factory=lambda: np.zeros(3))
    pose_offset_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    pose_depth_m: float = 4.0

    def __post_init__(self) -> None:
        shift = np.array(self.shift_m, dtype=np.float64)
        k = shift.shape[0] if shift.ndim == 2 else -1
        object.__setattr__(self, "shift_m", _vector("shift_m", shift, (k, 2)))
        object.__setattr__(self, "rotation_rad", _vector("rotation_rad", self.rotation_rad, (k,)))
        for name, default in (("gain", 1.0), ("offset_v", 0.0)):
            value = getattr(self, name)
            value = np.full(k, default) if np.size(value) == 0 else value
            object.__setattr__(self, name, _vector(name, value, (k,)))
        if not (math.isfinite(self.gamma) and self.gamma > 0):
            raise ValueError(f"PerturbationDraw.gamma = {self.gamma!r} is invalid: allowed > 0")
        if not abs(self.dot_gain) <= 0.25:
            raise ValueError(
                f"PerturbationDraw.dot_gain = {self.dot_gain!r} is invalid: allowed [-0.25, 0.25]"
            )
        if not (math.isfinite(self.blur_sigma_m) and self.blur_sigma_m >= 0):
            raise ValueError(
                f"PerturbationDraw.blur_sigma_m = {self.blur_sigma_m!r} m is invalid: "
                "allowed a finite number >= 0"
            )
        if not (self.gain > 0).all():
            raise ValueError(f"PerturbationDraw.gain = {self.gain!r} is invalid: allowed > 0")
        for name in ("pose_rotation_rad", "pose_offset_m"):
            object.__setattr__(self, name, _vector(name, getattr(self, name), (3,)))
        if not (math.isfinite(self.pose_depth_m) and self.pose_depth_m > 0):
            raise ValueError(
                f"PerturbationDraw.pose_depth_m = {self.pose_depth_m!r} m is invalid: "
                "allowed a finite depth > 0"
            )

    @property
    def has_pose_error(self) -> bool:
        """Whether the camera is off its designed pose (orientation or position)."""
        return bool(self.pose_rotation_rad.any() or self.pose_offset_m.any())

    @property
    def num_pixels(self) -> int:
        """Number of freeform pixels the draw is for."""
        return int(self.shift_m.shape[0])

    @classmethod
    def identity(cls, num_pixels: int) -> PerturbationDraw:
        """The camera as designed, for ``num_pixels`` pixels."""
        return cls(shift_m=np.zeros((num_pixels, 2)), rotation_rad=np.zeros(num_pixels))

    def without_pose(self) -> PerturbationDraw:
        """This draw with the camera at its designed pose (masks, print and diodes kept)."""
        return replace(self, pose_rotation_rad=np.zeros(3), pose_offset_m=np.zeros(3))

    def transmittance_range(self, nominal: tuple[float, float]) -> tuple[float, float]:
        """The printed ``(lo, hi)`` transmittance for the ``nominal`` range, kept in [0, 1].

        Raises:
            ValueError: the errors leave no range (``lo >= hi``).
        """
        lo = min(max(nominal[0] + self.min_transmittance_error, 0.0), 1.0)
        hi = min(max(nominal[1] + self.max_transmittance_error, 0.0), 1.0)
        if not lo < hi:
            raise ValueError(
                f"printed transmittance range ({lo:g}, {hi:g}) is empty: the errors "
                f"{self.min_transmittance_error:g}, {self.max_transmittance_error:g} are too large "
                f"for the nominal range {nominal}"
            )
        return lo, hi


def _trusted_draw(**values: object) -> PerturbationDraw:
    """A :class:`PerturbationDraw` of values known valid (float64 arrays of the right shapes)."""
    draw = object.__new__(PerturbationDraw)
    for name, value in values.items():
        object.__setattr__(draw, name, value)
    return draw
