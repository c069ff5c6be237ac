r"""Differential rendering: a converged static background plus what the movers change.

Most of an indoor scene does not move: people and a door change a few per cent
of the light a detector receives, while walls, furniture, lamps and daylight
stay put or drift slowly. A frame at time ``t`` in the background window
``[t_0, t_0 + \Delta)`` (``interval_s``) is estimated as

.. math::

    \hat T(\text{frame}) = B(t) + X(\text{frame}; s) - C(s), \qquad
    B(t) = (1 - \alpha) D(t_0) + \alpha D(t_0 + \Delta) + \sum_{i\,\text{on}} L_i,
    \qquad \alpha = (t - t_0) / \Delta

- ``B(t)``: the frame's *background* (its scene with the movers removed and the
  frame's lights), as a weighted sum of *components* rendered once per
  dataset at many samples and the full path depth (light transport is linear
  in the emitters): ``D``, the daylight with every light off, at the ends of
  the window (the end of one window is the start of the next), and ``L_i``,
  light ``i`` alone. Lights switching on and off then cost no new render, and
  linear interpolation follows the daylight's slow drift (a few per cent of the
  light per minute in the time-lapsed workspace) to second order; the fidelity
  module measures what it leaves. The family names the components and their
  weights (``background_components``);
- ``X``: the frame's movers, door and lights with the daylight of ``t_0``, at
  few samples, path depth ``d`` (the fidelity module uses the backgrounds')
  and seed ``s``;
- ``C``: the background at ``t_0`` (the frame's lights) with the same samples,
  depth and seed ``s``.

``X`` and ``C`` see the same light and use common random numbers (same seed,
same wavefront): a path that never meets a mover is the same path in both, so it
cancels exactly, and the noise of ``X - C`` comes only from paths that meet a
person or the door. ``E[X - C]`` is the light the movers change at ``t_0``, so
the estimate is unbiased up to the movers' effect on bounces deeper than ``d``,
the change of that effect within the window, and the interpolation of the
background (the interpolation is measured by :mod:`mincam_render.render.fidelity`,
and every term by its check against a plain reference). This is Debevec's
differential rendering (1998) with common random numbers instead of a
photographed background.

With several detectors, ``X - C`` can be rendered once from the board centre
and added to every detector's own background (``shared_difference``): parallax
then acts on the movers' change only, a few per cent of the light, while ``B``
keeps each detector's exact view; the fidelity module measures the error this
adds.

The seed ``s`` is shared by every frame of a background window
(:attr:`DifferenceSeeds.WINDOW`: ``C`` is rendered once per window), which makes
the residual noise of ``X - C`` a pattern repeated across those frames; or each
frame has its own (:attr:`DifferenceSeeds.FRAME`: ``C`` is rendered again with
every frame, twice the frames' paths) and its noise is new in every frame. Each
frame is an unbiased estimate either way. ``\hat T`` can be slightly negative in
texels where noise exceeds the light (it is stored as is: clamping would bias).
"""

from __future__ import annotations

import enum
import hashlib
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol, cast

import numpy as np

from mincam_render.core.seeds import stream_seed
from mincam_render.core.strict_json import JsonObject
from mincam_render.optics.camera import FreeformCamera
from mincam_render.render.capabilities import DifferentialBackground

if TYPE_CHECKING:
    import mitsuba as mi

    class EstimatorFamily(Protocol):
        """A scene family's estimator, which every render of a dataset goes through.

        Structural: ``render`` sits below ``scenes`` in the layers and does not import it.
        """

        def render_transport(
            self,
            scene: mi.Scene,
            camera: FreeformCamera,
            *,
            spp: int,
            seed: int,
            max_depth: int | None = None,
            parallax: bool = True,
        ) -> np.ndarray:
            """Transport images ``[detector, row, col]`` (W, numpy) with the family's estimator."""

    class BackgroundFamily(DifferentialBackground, EstimatorFamily, Protocol):
        """What differential rendering needs of a scene family: its background and estimator."""


def background_family(family: object) -> BackgroundFamily:
    """``family`` as a family with a differential background, checked.

    Raises:
        ValueError: it declares none (:class:`DifferentialBackground`), e.g. a
            dataset planned with backgrounds whose family's code has changed since.
    """
    if not isinstance(family, DifferentialBackground):
        name = getattr(family, "name", type(family).__name__)
        raise ValueError(
            f"family {name!r} has no static background (DifferentialBackground): "
            "differential rendering is unavailable"
        )
    return cast("BackgroundFamily", family)


class DifferenceSeeds(enum.StrEnum):
    """Which frames share the seed of ``X - C`` (see the module doc)."""

    WINDOW = "window"  # every frame of a background window: C rendered once per window
    FRAME = "frame"  # each frame its own: C rendered with every frame (twice the paths)


@dataclass(frozen=True)
class BackgroundSettings:
    """How backgrounds are rendered (recorded in a dataset's manifest).

    Args:
        interval_s: scene time (s) a background's daylight stands for.
        spp: samples per texel of the converged background ``B``.
        max_depth: path depth of ``B`` (None: the scene's integrator).
        shared_difference: render ``X`` and ``C`` once, from the board centre,
            for all detectors (``B`` stays per detector).
        difference_seeds: which frames share the seed of ``X - C``
            (:class:`DifferenceSeeds`).
        seeds_recorded: False for a record written before ``difference_seeds``
            existed (plans shipped then): :meth:`as_json` leaves it out again,
            so a record is written back as it was read.
    """

    interval_s: float
    spp: int
    max_depth: int | None
    shared_difference: bool = False
    difference_seeds: DifferenceSeeds = DifferenceSeeds.WINDOW
    seeds_recorded: bool = field(default=True, compare=False, repr=False)

    @classmethod
    def from_dict(cls, d: dict) -> BackgroundSettings:
        """From a manifest's ``job.render.background`` (``max_depth`` 0: the scene's).

        Manifests without ``difference_seeds`` (format 4 before it) shared the window's.
        """
        return cls(
            interval_s=float(d["interval_s"]),
            spp=int(d["spp"]),
            max_depth=int(d["max_depth"]) or None,
            shared_difference=bool(d.get("shared_difference", False)),
            difference_seeds=DifferenceSeeds(d.get("difference_seeds", "window")),
            seeds_recorded="difference_seeds" in d,
        )

    def as_json(self) -> JsonObject:
        """The record :meth:`from_dict` reads (``max_depth`` 0: the scene's integrator)."""
        record: JsonObject = {
            "interval_s": self.interval_s,
            "spp": self.spp,
            "max_depth": self.max_depth or 0,
            "shared_difference": self.shared_difference,
        }
        if self.seeds_recorded:
            record["difference_seeds"] = self.difference_seeds.value
        return record

    def __post_init__(self) -> None:
        if not self.interval_s > 0:
            raise ValueError(f"interval_s = {self.interval_s!r}: allowed a number > 0 (s)")
        if not 1 <= self.spp <= 1 << 20:
            raise ValueError(f"spp = {self.spp!r}: allowed an integer in [1, 2^20]")
        try:
            object.__setattr__(self, "difference_seeds", DifferenceSeeds(self.difference_seeds))
        except ValueError:
            allowed = [v.value for v in DifferenceSeeds]
            raise ValueError(
                f"difference_seeds = {self.difference_seeds!r}: allowed one of {allowed}"
            ) from None


@dataclass(frozen=True)
class Background:
    """A rendered background (numpy arrays ``[detector, row, col]``, W).

    Args:
        key: the family's background key.
        interval_s: the window the key was made with (s).
        seed: seed ``s`` of ``same_seed_w`` (shared by every frame of this
            background with ``DifferenceSeeds.WINDOW``; each frame's own is
            :meth:`frame_seed`).
        components: ``{component key: converged render}`` of every component its
            frames use (many samples, full depth, per detector; shared with
            other backgrounds).
        same_seed_w: ``C``, the frames' samples, depth and seed at the window's
            start; ``[1, row, col]`` (board centre) when the difference is shared.
        difference_seeds: which frames share the seed of ``X - C``.
    """

    key: str
    interval_s: float
    seed: int
    components: dict[str, np.ndarray]
    same_seed_w: np.ndarray
    difference_seeds: DifferenceSeeds = DifferenceSeeds.WINDOW

    def frame_seed(self, index: int) -> int:
        """Seed of ``X - C`` of frame ``index``: the window's, or a stream of it per frame."""
        if self.difference_seeds is DifferenceSeeds.WINDOW:
            return self.seed
        return stream_seed(self.seed, "differential/frame", index)

    @property
    def shared_difference(self) -> bool:
        """Whether frames render ``X`` once, from the board centre (``C`` has one detector)."""
        return self.same_seed_w.shape[0] == 1 < self.detectors

    @property
    def detectors(self) -> int:
        """Detectors of the converged renders (those of ``C`` when there are none)."""
        for array in self.components.values():
            return array.shape[0]
        return self.same_seed_w.shape[0]

    def converged(self, weights: dict[str, float]) -> np.ndarray:
        """``sum_j w_j R_j`` in float64 (W) for ``{component key: weight}``.

        Raises:
            ValueError: a component is not among :attr:`components`.
        """
        missing = sorted(set(weights) - set(self.components))
        if missing:
            raise ValueError(f"background {self.key!r} has no component(s) {missing}")
        total = np.zeros((self.detectors, *self.same_seed_w.shape[1:]), dtype=np.float64)
        for key, w in sorted(weights.items()):  # a fixed order: same bytes every time
            if w != 0.0:
                total += w * self.components[key].astype(np.float64)
        return total


def background_seed(dataset_seed: int, key: str) -> int:
    """Seed ``s`` of a background: a hash of the dataset seed and the key, in [0, 2^63)."""
    digest = hashlib.sha256(f"{int(dataset_seed)}|{key}".encode()).digest()
    return int.from_bytes(digest[:8], "little") & (2**63 - 1)


def component_seed(dataset_seed: int, key: str) -> int:
    """Seed of the converged render of background component ``key``."""
    return background_seed(dataset_seed, f"component|{key}")


def background_parts(
    family: BackgroundFamily, num_frames: int, interval_s: float
) -> dict[str, list[str]]:
    """``{background key: its component keys}`` over frames ``[0, num_frames)``, first-use order."""
    parts: dict[str, list[str]] = {}
    for i in range(num_frames):
        key = family.background_key(i, interval_s)
        if key not in parts:
            parts[key] = sorted(family.background_components(i, interval_s))
    return parts


def render_same_seed(
    family: BackgroundFamily,
    scene: mi.Scene,
    camera: FreeformCamera,
    index: int,
    settings: BackgroundSettings,
    *,
    dataset_seed: int,
    spp: int,
    max_depth: int | None,
) -> tuple[str, int, np.ndarray]:
    """``(key, seed s, C)`` of frame ``index``'s background; leaves ``scene`` at it.

    ``C`` is the background at its window's start with the frames' samples,
    depth and seed (``[1, row, col]`` from the board centre when shared).
    """
    key = family.background_key(index, settings.interval_s)
    seed = background_seed(dataset_seed, key)
    family.set_background(scene, index, settings.interval_s)
    same_seed = family.render_transport(
        scene,
        camera.rendered_camera(settings.shared_difference),
        spp=spp,
        seed=seed,
        max_depth=max_depth,
    )
    return key, seed, same_seed


def render_component(
    family: BackgroundFamily,
    scene: mi.Scene,
    camera: FreeformCamera,
    key: str,
    settings: BackgroundSettings,
    *,
    dataset_seed: int,
) -> np.ndarray:
    """The converged render of background component ``key`` (``[detector, row, col]``, W)."""
    family.set_background_component(scene, key)
    return family.render_transport(
        scene,
        camera,
        spp=settings.spp,
        seed=component_seed(dataset_seed, key),
        max_depth=settings.max_depth,
    )


def render_background(
    family: BackgroundFamily,
    scene: mi.Scene,
    camera: FreeformCamera,
    index: int,
    settings: BackgroundSettings,
    *,
    dataset_seed: int,
    spp: int,
    max_depth: int | None,
    component_cache: dict[str, np.ndarray] | None = None,
) -> Background:
    """Render the background of frame ``index``: its components and ``C``.

    Leaves ``scene`` at the background's start.

    Args:
        family: a family with a differential background.
        scene: the family's scene (Mitsuba), updated in place.
        camera: the dataset's camera (components are rendered per detector).
        index: any frame of the background.
        settings: how components are rendered.
        dataset_seed: the dataset's seed (seeds derive from it and the keys).
        spp: the frames' samples per texel (for ``C``).
        max_depth: the frames' path depth (for ``C``; None: the scene's integrator).
        component_cache: ``{component key: render}`` already made with these
            settings (read and extended): components are shared between
            backgrounds, and a key's seed is fixed, so a cached render is the
            one a new render would give.
    """
    cache = {} if component_cache is None else component_cache
    # every frame of this background uses the same components (its lights, its window)
    parts = family.background_components(index, settings.interval_s)
    for part in parts:
        if part not in cache:
            cache[part] = render_component(
                family, scene, camera, part, settings, dataset_seed=dataset_seed
            )
    key, seed, same_seed = render_same_seed(
        family,
        scene,
        camera,
        index,
        settings,
        dataset_seed=dataset_seed,
        spp=spp,
        max_depth=max_depth,
    )
    return Background(
        key=key,
        interval_s=settings.interval_s,
        seed=seed,
        components={part: cache[part] for part in parts},
        same_seed_w=same_seed,
        difference_seeds=settings.difference_seeds,
    )


def render_frame(
    family: BackgroundFamily,
    scene: mi.Scene,
    camera: FreeformCamera,
    index: int,
    background: Background,
    *,
    spp: int,
    max_depth: int | None,
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """``(B(t) + X - C, labels)`` of frame ``index`` (W, ``[detector, row, col]``).

    ``X`` and ``C`` at :meth:`Background.frame_seed`: ``C`` is the window's
    (``same_seed_w``) when frames share its seed, else rendered with the frame's.

    Raises:
        ValueError: ``background`` is not frame ``index``'s.
    """
    key = family.background_key(index, background.interval_s)
    if key != background.key:
        raise ValueError(f"frame {index} has background {key!r}, not {background.key!r}")
    diff_cam = camera.rendered_camera(background.shared_difference)
    seed = background.frame_seed(index)
    same_seed = background.same_seed_w
    if background.difference_seeds is DifferenceSeeds.FRAME:
        family.set_background(scene, index, background.interval_s)
        same_seed = family.render_transport(
            scene, diff_cam, spp=spp, seed=seed, max_depth=max_depth
        )
    labels = family.set_frame_in_window(scene, index, background.interval_s)
    x = family.render_transport(scene, diff_cam, spp=spp, seed=seed, max_depth=max_depth)
    # [1, R, C] differences broadcast over the detectors' own backgrounds
    converged = background.converged(family.background_components(index, background.interval_s))
    estimate = converged + x - same_seed
    return estimate.astype(np.float32), labels
