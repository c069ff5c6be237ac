"""Geometry and electronics of a freeform-pixel camera.

A freeform pixel is a photodiode on a circuit board with a printed mask parallel
to the board, ``mask_distance_m`` in front of it. All lengths are in metres.

Board frame (used for detector positions): the board's origin is ``position``;
``forward`` points from ``position`` toward ``look_at``; ``up`` is the given
``up`` made orthogonal to ``forward``; ``right = forward x up``. A detector at
board coordinates ``(x, y)`` sits at ``position + x*right + y*up``, and its mask
is centred ``mask_distance_m`` in front of it along ``forward``.

Mask texel ``(v, u)`` of ``T[k, v, u]``: row 0 is the ``up`` edge of the mask,
column 0 its left edge (``-right``), as in an ordinary photo seen from the camera.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from mincam_render.core.checks import check_int, check_number

MM = 1e-3  #: metres per millimetre

#: Defaults of the paper's prototype (Klotz & Nayar, "Minimalist Vision with
#: Freeform Pixels", Sec. 6 and supplement B): Hamamatsu S9119-01 photodiode,
#: 0.88 x 0.88 mm active area; 16 x 16 mm masks 11.4 mm above the diode;
#: transimpedance gain 1e7 V/A; read noise 400 uV; 16-bit ADC saturating at 3.2 V;
#: printable transmittance 0.01-0.67.
PROTOTYPE_DETECTOR_SIZE_M = 0.88 * MM
PROTOTYPE_MASK_SIZE_M = 16.0 * MM
PROTOTYPE_MASK_DISTANCE_M = 11.4 * MM
PROTOTYPE_GAIN_V_PER_A = 1e7
PROTOTYPE_READ_NOISE_V = 400e-6
PROTOTYPE_ADC_BITS = 16
PROTOTYPE_FULL_SCALE_V = 3.2
PROTOTYPE_TRANSMITTANCE_RANGE = (0.01, 0.67)
#: Not in the paper: a typical peak responsivity of a visible-compensated silicon
#: photodiode. Replace it with the value of your diode's datasheet.
TYPICAL_RESPONSIVITY_A_PER_W = 0.3
#: Not in the paper (it says "a small positive value"): slope above saturation.
DEFAULT_SATURATION_SLOPE = 0.01
#: Prototype read-out rate (30 frames/s); sets the shot-noise integration time.
DEFAULT_INTEGRATION_TIME_S = 1.0 / 30.0


def _fail(owner: str, name: str, value: object, unit: str, allowed: str) -> ValueError:
    unit_txt = f" {unit}" if unit else ""
    return ValueError(f"{owner}.{name} = {value!r}{unit_txt} is invalid: allowed {allowed}")


#: Largest coordinate of a camera point or direction (m). From about 1e77 m the
#: squared length of a cross product of two such vectors overflows float64; a
#: camera merely far from its scene is refused by the scene check, which names
#: the ``--position`` option.
MAX_COORD_M = 1e50


def _check_vec3(owner: str, name: str, value: object) -> tuple[float, float, float]:
    expected = f"3 finite numbers (x, y, z), each within ±{MAX_COORD_M:g}"
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise _fail(owner, name, value, "m", expected) from None
    if arr.shape != (3,) or not np.all(np.abs(arr) <= MAX_COORD_M):
        raise _fail(owner, name, value, "m", expected)
    return (float(arr[0]), float(arr[1]), float(arr[2]))


@dataclass(frozen=True, kw_only=True)
class DirectionalResponse:
    """A photodiode's angular sensitivity beyond Lambert's cosine.

    The sensitivity of a flat detector to a ray at angle ``theta`` from its
    normal is ``cos(theta) * f(theta)``; this table gives ``f`` (1 at normal
    incidence for most diodes), linearly interpolated, as read off a datasheet's
    "directional characteristics" plot divided by ``cos(theta)``.

    Args:
        angles_deg: increasing angles from the normal, first 0, last <= 90 (deg).
        relative_sensitivity: ``f`` at those angles, each in [0, 10].

    """

    angles_deg: tuple[float, ...]
    relative_sensitivity: tuple[float, ...]

    def __post_init__(self) -> None:
        owner = "DirectionalResponse"
        angles = tuple(
            check_number(f"{owner}.angles_deg", a, 0.0, 90.0, unit="deg", numpy=True)
            for a in self.angles_deg
        )
        values = tuple(
            check_number(f"{owner}.relative_sensitivity", s, 0.0, 10.0, numpy=True)
            for s in self.relative_sensitivity
        )
        if len(angles) < 2 or len(angles) != len(values):
            raise _fail(
                owner,
                "angles_deg",
                self.angles_deg,
                "deg",
                f"at least 2 angles, as many as relative_sensitivity ({len(values)})",
            )
        if angles[0] != 0.0 or any(b <= a for a, b in zip(angles, angles[1:], strict=False)):
            raise _fail(owner, "angles_deg", self.angles_deg, "deg", "strictly increasing from 0")
        object.__setattr__(self, "angles_deg", angles)
        object.__setattr__(self, "relative_sensitivity", values)

    def __call__(self, theta_rad: np.ndarray) -> np.ndarray:
        """Evaluate ``f`` (numpy) at angles in radians; beyond the table it is held."""
        return np.interp(np.degrees(theta_rad), self.angles_deg, self.relative_sensitivity)

    def uniform_table(self, n: int = 181) -> np.ndarray:
        """``f`` sampled at ``n`` uniform angles over [0, 90] deg (float32), for lookups."""
        return self(np.radians(np.linspace(0.0, 90.0, n))).astype(np.float32)


@dataclass(frozen=True, kw_only=True)
class DetectorElectronics:
    """Photodiode and read-out chain of one freeform pixel (paper eqs. 3-4).

    Args:
        responsivity_a_per_w: photocurrent per watt on the diode (A/W), (0, 10].
        gain_v_per_a: transimpedance gain (V/A), [1, 1e12].
        read_noise_v: standard deviation of Gaussian read noise (V), [0, 10].
        adc_bits: ADC resolution, [1, 32].
        full_scale_v: voltage at which the ADC saturates (V), (0, 1000].
        saturation_slope: slope ``alpha`` above full scale (leaky saturation,
            paper eq. 5), (0, 1].
        integration_time_s: exposure per measurement, sets photon shot noise (s).
        dark_current_a: diode dark current (A), [0, 1e-3].

    """

    responsivity_a_per_w: float = TYPICAL_RESPONSIVITY_A_PER_W
    gain_v_per_a: float = PROTOTYPE_GAIN_V_PER_A
    read_noise_v: float = PROTOTYPE_READ_NOISE_V
    adc_bits: int = PROTOTYPE_ADC_BITS
    full_scale_v: float = PROTOTYPE_FULL_SCALE_V
    saturation_slope: float = DEFAULT_SATURATION_SLOPE
    integration_time_s: float = DEFAULT_INTEGRATION_TIME_S
    dark_current_a: float = 0.0

    def __post_init__(self) -> None:
        for name, lo, hi, unit, lo_open in (
            ("responsivity_a_per_w", 0, 10, "A/W", True),
            ("gain_v_per_a", 1.0, 1e12, "V/A", False),
            ("read_noise_v", 0.0, 10.0, "V", False),
            ("full_scale_v", 0.0, 1000.0, "V", True),
            ("saturation_slope", 0.0, 1.0, "", True),
            ("integration_time_s", 0, 3600, "s", True),
            ("dark_current_a", 0.0, 1e-3, "A", False),
        ):
            value = getattr(self, name)
            owner = f"DetectorElectronics.{name}"
            check_number(owner, value, lo, hi, unit=unit, lo_open=lo_open, numpy=True)
        check_int("DetectorElectronics.adc_bits", self.adc_bits, 1, 32, numpy=True)

    @property
    def lsb_v(self) -> float:
        """Voltage of one ADC least significant bit (V)."""
        return self.full_scale_v / 2.0**self.adc_bits


@dataclass(frozen=True, kw_only=True)
class DetectorLayout:
    """Detector centres on the board, in board coordinates (metres).

    Build one with :meth:`grid`, :meth:`row`, or explicit ``positions_m``.

    Args:
        positions_m: ``((x, y), ...)`` board coordinates of each detector (m).

    """

    positions_m: tuple[tuple[float, float], ...]

    def __post_init__(self) -> None:
        owner = "DetectorLayout"
        try:
            arr = np.asarray(self.positions_m, dtype=np.float64)
        except (TypeError, ValueError):
            raise _fail(owner, "positions_m", self.positions_m, "m", "a list of (x, y)") from None
        if arr.ndim != 2 or arr.shape[1] != 2 or not 1 <= arr.shape[0] <= 4096:
            raise _fail(
                owner, "positions_m", self.positions_m, "m", "1 to 4096 pairs (x, y) of numbers"
            )
        if not np.all(np.isfinite(arr)) or np.any(np.abs(arr) > 10.0):
            raise _fail(owner, "positions_m", self.positions_m, "m", "finite, |x|, |y| <= 10 m")
        object.__setattr__(self, "positions_m", tuple((float(x), float(y)) for x, y in arr))

    @classmethod
    def grid(cls, *, rows: int, cols: int, pitch_m: float) -> DetectorLayout:
        """A centred ``rows x cols`` grid, detector 0 at the top left, row-major."""
        check_int("DetectorLayout.grid.rows", rows, 1, 64, numpy=True)
        check_int("DetectorLayout.grid.cols", cols, 1, 64, numpy=True)
        check_number(
            "DetectorLayout.grid.pitch_m", pitch_m, 0.0, 1.0, unit="m", lo_open=True, numpy=True
        )
        xs = (np.arange(cols) - (cols - 1) / 2.0) * pitch_m
        ys = ((rows - 1) / 2.0 - np.arange(rows)) * pitch_m
        return cls(positions_m=tuple((float(x), float(y)) for y in ys for x in xs))

    @classmethod
    def row(cls, *, count: int, pitch_m: float) -> DetectorLayout:
        """``count`` detectors in a centred horizontal row."""
        return cls.grid(rows=1, cols=count, pitch_m=pitch_m)

    @property
    def count(self) -> int:
        """Number of detectors."""
        return len(self.positions_m)


def _prototype_layout() -> DetectorLayout:
    # The prototype has 24 pixels; a 4 x 6 grid at 20 mm pitch leaves room
    # between the 16 mm masks.
    return DetectorLayout.grid(rows=4, cols=6, pitch_m=20 * MM)


@dataclass(frozen=True, kw_only=True)
class FreeformCamera:
    """A camera of freeform pixels: detectors, masks, board pose and electronics.

    Defaults reproduce the paper's prototype (see the ``PROTOTYPE_*`` constants).

    Args:
        detector_size_m: side of the square active area (m), (0, 0.1].
        mask_size_m: side of each square mask (m), (0, 1].
        mask_distance_m: mask plane distance in front of the detector (m), (0, 1].
        mask_resolution: ``(rows, cols)`` of mask texels, each in [1, 4096].
        layout: detector positions on the board.
        position: board origin in the world (m).
        look_at: a world point the board faces (m).
        up: world direction that becomes row 0 of the masks.
        directional_response: angular sensitivity beyond cosine; None = Lambert only.
        electronics: photodiode and read-out chain.
        transmittance_range: ``(min, max)`` printable transmittance, 0 <= min < max <= 1.

    """

    detector_size_m: float = PROTOTYPE_DETECTOR_SIZE_M
    mask_size_m: float = PROTOTYPE_MASK_SIZE_M
    mask_distance_m: float = PROTOTYPE_MASK_DISTANCE_M
    mask_resolution: tuple[int, int] = (32, 32)
    layout: DetectorLayout = field(default_factory=_prototype_layout)
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    look_at: tuple[float, float, float] = (0.0, 0.0, 1.0)
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)
    directional_response: DirectionalResponse | None = None
    electronics: DetectorElectronics = field(default_factory=DetectorElectronics)
    transmittance_range: tuple[float, float] = PROTOTYPE_TRANSMITTANCE_RANGE

    def __post_init__(self) -> None:
        o = "FreeformCamera"
        # > 0: a point detector receives no power; its limit is T / area as area -> 0
        for name, hi in (("detector_size_m", 0.1), ("mask_size_m", 1.0), ("mask_distance_m", 1.0)):
            value = getattr(self, name)
            check_number(f"{o}.{name}", value, 0.0, hi, unit="m", lo_open=True, numpy=True)
        res = self.mask_resolution
        if not isinstance(res, tuple | list) or len(res) != 2:
            raise _fail(o, "mask_resolution", res, "texels", "(rows, cols), each in [1, 4096]")
        rows = check_int(f"{o}.mask_resolution", res[0], 1, 4096, numpy=True)
        cols = check_int(f"{o}.mask_resolution", res[1], 1, 4096, numpy=True)
        object.__setattr__(self, "mask_resolution", (rows, cols))
        if not isinstance(self.layout, DetectorLayout):
            raise _fail(o, "layout", self.layout, "", "a DetectorLayout")
        if not isinstance(self.electronics, DetectorElectronics):
            raise _fail(o, "electronics", self.electronics, "", "a DetectorElectronics")
        dr_ = self.directional_response
        if dr_ is not None and not isinstance(dr_, DirectionalResponse):
            raise _fail(o, "directional_response", dr_, "", "None or a DirectionalResponse")
        for name in ("position", "look_at", "up"):
            object.__setattr__(self, name, _check_vec3(o, name, getattr(self, name)))
        fwd = np.subtract(self.look_at, self.position)
        if np.linalg.norm(fwd) < 1e-9:
            raise _fail(o, "look_at", self.look_at, "m", "a point different from position")
        up = np.asarray(self.up)
        if np.linalg.norm(up) < 1e-12 or np.linalg.norm(np.cross(fwd, up)) < 1e-9 * np.linalg.norm(
            up
        ) * np.linalg.norm(fwd):
            raise _fail(
                o, "up", self.up, "", "a non-zero direction not parallel to look_at - position"
            )
        tr = self.transmittance_range
        if not isinstance(tr, tuple | list) or len(tr) != 2:
            raise _fail(o, "transmittance_range", tr, "", "(min, max) with 0 <= min < max <= 1")
        lo = check_number(f"{o}.transmittance_range", tr[0], 0.0, 1.0, numpy=True)
        hi = check_number(f"{o}.transmittance_range", tr[1], 0.0, 1.0, numpy=True)
        if not lo < hi:
            raise _fail(o, "transmittance_range", tr, "", "(min, max) with 0 <= min < max <= 1")
        object.__setattr__(self, "transmittance_range", (lo, hi))
        pos = np.asarray(self.layout.positions_m)
        if len(pos) > 1:
            d = np.abs(pos[:, None, :] - pos[None, :, :]).max(axis=-1)
            np.fill_diagonal(d, np.inf)
            if d.min() < self.mask_size_m - 1e-12:
                raise _fail(
                    o,
                    "layout",
                    f"closest detectors {d.min() / MM:.3g} mm apart",
                    "",
                    f"detectors at least mask_size_m = {self.mask_size_m / MM:.3g} mm apart "
                    "(masks may not overlap)",
                )

    # ---- derived geometry (numpy, float64, metres) ---------------------------------

    @property
    def num_detectors(self) -> int:
        """Number of freeform pixels ``K``."""
        return self.layout.count

    @property
    def frame(self) -> np.ndarray:
        """World axes of the board as rows ``[right, up, forward]``, shape (3, 3)."""
        fwd = np.subtract(self.look_at, self.position)
        fwd = fwd / np.linalg.norm(fwd)
        up = np.asarray(self.up, dtype=np.float64)
        up = up - fwd * np.dot(up, fwd)
        up /= np.linalg.norm(up)
        right = np.cross(fwd, up)
        return np.stack([right, up, fwd])

    def centre_camera(self) -> FreeformCamera:
        """This camera with one detector at the board centre (shared renders)."""
        return replace(self, layout=DetectorLayout(positions_m=((0.0, 0.0),)))

    def rendered_camera(self, shared: bool) -> FreeformCamera:
        """The camera a render uses: :meth:`centre_camera` if ``shared``, else this one."""
        return self.centre_camera() if shared else self

    @property
    def detector_centers_m(self) -> np.ndarray:
        """World positions of detector centres, shape (K, 3), metres."""
        right, up, _ = self.frame
        xy = np.asarray(self.layout.positions_m)
        return np.asarray(self.position) + xy[:, :1] * right + xy[:, 1:] * up

    @property
    def texel_size_m(self) -> tuple[float, float]:
        """Texel ``(height, width)`` on the mask (m)."""
        rows, cols = self.mask_resolution
        return (self.mask_size_m / rows, self.mask_size_m / cols)

    @property
    def fov_deg(self) -> float:
        """Full field of view of one pixel across the mask, from the detector centre (deg)."""
        return math.degrees(2.0 * math.atan(0.5 * self.mask_size_m / self.mask_distance_m))

    def texel_centers_m(self, detector: int) -> np.ndarray:
        """World positions of the mask texel centres of one detector, shape (rows, cols, 3)."""
        rows, cols = self.mask_resolution
        right, up, fwd = self.frame
        s = (np.arange(cols) + 0.5) / cols * self.mask_size_m - 0.5 * self.mask_size_m
        t = 0.5 * self.mask_size_m - (np.arange(rows) + 0.5) / rows * self.mask_size_m
        c = self.detector_centers_m[detector] + self.mask_distance_m * fwd
        return c + s[None, :, None] * right + t[:, None, None] * up

    def project_to_texel(self, point_m: np.ndarray, detector: int) -> tuple[float, float]:
        """Continuous ``(row, col)`` where the ray detector-centre -> point crosses the mask.

        Row/col are in texel units, 0 at the top-left corner of texel (0, 0).

        Raises:
            ValueError: the point is not in front of the board.

        """
        right, up, fwd = self.frame
        rel = np.asarray(point_m, dtype=np.float64) - self.detector_centers_m[detector]
        depth = float(np.dot(rel, fwd))
        if depth <= 0:
            raise ValueError(f"point {point_m} is behind the board of the camera")
        s = np.dot(rel, right) * self.mask_distance_m / depth
        t = np.dot(rel, up) * self.mask_distance_m / depth
        rows, cols = self.mask_resolution
        col = (s + 0.5 * self.mask_size_m) / self.mask_size_m * cols
        row = (0.5 * self.mask_size_m - t) / self.mask_size_m * rows
        return (row, col)

    def to_dict(self) -> dict:
        """A JSON-ready description (SI units) for manifests and sidecars."""
        from dataclasses import asdict

        return asdict(self)
