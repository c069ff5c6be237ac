"""The description of a user's Mitsuba scene as a task: movers, switched emitters, labels.

Frozen, keyword-only dataclasses in SI units (m, s, m/s), read from TOML by
:func:`mincam_render.core.config.parse`. Each validates what it can without the
scene (ranges, one of region or path, labels that name what exists in the
description); what needs the scene -- shape and emitter ids, regions inside the
scene, movers the camera sees -- is checked by :mod:`.layout` when the family is
built. Every error names the field (``movers[1].region``, ``labels[0].mover``).
"""

from __future__ import annotations

import enum
import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

from mincam_render.core.config import Described, check_min_max, spec
from mincam_render.core.labels import LabelKind
from mincam_render.scenes.base import CameraMount

T = TypeVar("T")


@dataclass(frozen=True, kw_only=True)
class Box:
    """An axis-aligned box in world coordinates (m); a zero extent on an axis fixes it."""

    min_m: tuple[float, float, float] = spec(unit="m", doc="corner with the smallest x, y, z")
    max_m: tuple[float, float, float] = spec(unit="m", doc="corner with the largest x, y, z")

    def __post_init__(self) -> None:
        if any(lo > hi for lo, hi in zip(self.min_m, self.max_m, strict=True)):
            raise ValueError(
                f"min_m = {list(self.min_m)}, max_m = {list(self.max_m)} m: min must not "
                "exceed max on any axis"
            )

    def contains(self, point_m: tuple[float, float, float], tolerance_m: float = 1e-9) -> bool:
        """Whether ``point_m`` (m) lies inside the box (closed, within ``tolerance_m``)."""
        return all(
            lo - tolerance_m <= p <= hi + tolerance_m
            for p, lo, hi in zip(point_m, self.min_m, self.max_m, strict=True)
        )


@dataclass(frozen=True, kw_only=True)
class Mover(Described):
    """A shape of the scene that moves within a region or along a path, and may come and go.

    Its *reference point* is the centre of its bounding box in the scene file; the
    region or the path is where that point goes (the shape is translated, never
    turned). Hidden, it is shrunk to nothing where it stands.
    """

    id: str = spec(doc="id of the shape in the Mitsuba scene (a mesh, rectangle, sphere, ...)")
    region: Box | None = spec(
        None,
        doc="box its reference point moves within: it appears at a uniformly random point "
        "and walks to random targets in it",
    )
    path: tuple[tuple[float, float, float], ...] = spec(
        (), unit="m", doc="waypoints its reference point follows in a closed loop (2 or more)"
    )
    speed_m_s: tuple[float, float] = spec(
        (0.0, 0.0),
        unit="m/s",
        range=(0.0, 1000.0),
        doc="min, max speed, drawn for each leg (region) or each appearance (path); 0 "
        "keeps it where it appears",
    )
    pause_s: tuple[float, float] = spec(
        (0.0, 0.0), unit="s", range=(0.0, 1e6), doc="min, max pause at each target of a region"
    )
    mean_present_s: float = spec(
        0.0,
        unit="s",
        range=(0.0, 1e7),
        doc="mean time it stays before it disappears (exponential; with mean_absent_s); 0: "
        "always there",
    )
    mean_absent_s: float = spec(
        0.0, unit="s", range=(0.0, 1e7), doc="mean time it is away before it appears again"
    )

    def __post_init__(self) -> None:
        if not self.id:
            raise ValueError("id = '': give the id of a shape in the scene")
        if (self.region is None) == (not self.path):
            raise ValueError(f"mover {self.id!r}: give exactly one of region or path")
        if self.path and len(self.path) < 2:
            raise ValueError(f"path = {[list(p) for p in self.path]}: allowed 2 or more waypoints")
        if (self.mean_present_s > 0) != (self.mean_absent_s > 0):
            raise ValueError(
                f"mean_present_s = {self.mean_present_s}, mean_absent_s = {self.mean_absent_s} "
                "s: give both (> 0) for a mover that comes and goes, or neither"
            )
        check_min_max(self, "speed_m_s", "pause_s")

    @property
    def switches(self) -> bool:
        """Whether it appears and disappears."""
        return self.mean_present_s > 0


@dataclass(frozen=True, kw_only=True)
class EmitterSwitch(Described):
    """An emitter of the scene switched on and off (a two-state Markov process)."""

    id: str = spec(doc="id of the emitter, or of the shape an area emitter is attached to")
    mean_on_s: float = spec(60.0, unit="s", range=(1e-3, 1e7), doc="mean time on (exponential)")
    mean_off_s: float = spec(60.0, unit="s", range=(1e-3, 1e7), doc="mean time off")


class LabelRule(enum.Enum):
    """What a label computes from the scene state."""

    COUNT_IN_REGION = "count_in_region"  # movers present with their reference point in region
    EMITTER_ON = "emitter_on"  # 0/1 per switched emitter
    POSITION = "position"  # a mover's reference point along one axis (m)
    SPEED = "speed"  # a mover's speed between frames (m/s)


class Axis(enum.Enum):
    """A world axis."""

    X = "x"
    Y = "y"
    Z = "z"


#: The fields each rule needs, beyond name and kind (the others must stay unset).
_RULE_FIELDS = {
    LabelRule.COUNT_IN_REGION: {"region", "movers"},
    LabelRule.EMITTER_ON: {"emitters"},
    LabelRule.POSITION: {"mover", "axis"},
    LabelRule.SPEED: {"mover"},
}
#: How each rule is learned and its median filter at evaluation (s): the paper's 2 s for
#: counts and speeds, 0.5 s for states.
RULE_LABELS = {
    LabelRule.COUNT_IN_REGION: (LabelKind.COUNT, 2.0, ""),
    LabelRule.EMITTER_ON: (LabelKind.BINARY, 0.5, ""),
    LabelRule.POSITION: (LabelKind.REGRESSION, 2.0, "m"),
    LabelRule.SPEED: (LabelKind.REGRESSION, 2.0, "m/s"),
}


@dataclass(frozen=True, kw_only=True)
class LabelDescription(Described):
    """One label, computed from each frame's state by its ``kind``."""

    name: str = spec(doc="key of the label in the dataset")
    kind: LabelRule = spec(doc="count_in_region, emitter_on, position or speed")
    region: Box | None = spec(None, doc="count_in_region: the box counted in")
    movers: tuple[str, ...] = spec((), doc="count_in_region: the movers counted (default all)")
    emitters: tuple[str, ...] = spec(
        (), doc="emitter_on: the switched emitters, one element each (default all)"
    )
    mover: str = spec("", doc="position, speed: the mover")
    axis: Axis | None = spec(None, doc="position: x, y or z")
    median_filter_s: float | None = spec(
        None, unit="s", range=(0.0, 3600.0), doc="median filter at evaluation (default by kind)"
    )

    def __post_init__(self) -> None:
        if not self.name:
            raise ValueError("name = '': give the label a name")
        needed = _RULE_FIELDS[self.kind]
        unset = {"region": None, "movers": (), "emitters": (), "mover": "", "axis": None}
        given = {f for f, empty in unset.items() if getattr(self, f) != empty}
        if extra := sorted(given - needed):
            raise ValueError(f"{extra[0]}: not a field of kind {self.kind.value!r}")
        if missing := sorted(needed - {"movers", "emitters"} - given):
            raise ValueError(f"{missing[0]}: required by kind {self.kind.value!r}")


@dataclass(frozen=True, kw_only=True)
class MitsubaConfig(Described):
    """A user's Mitsuba scene as a task (``family = "mitsuba"``; docs/your_own_task.md)."""

    scene: Path = spec(doc="the Mitsuba XML scene, relative to the description's folder")
    scene_sha256: str = spec(
        "",
        doc="sha256 of the scene file; empty: read from the file (a dataset records it, so "
        "an edited scene is another dataset)",
    )
    fps: float = spec(2.0, unit="1/s", range=(0.01, 1000.0), doc="frame rate")
    camera: CameraMount = spec(doc="the camera's mount: position, look_at, up, detectors")
    movers: tuple[Mover, ...] = spec((), doc="shapes that move, come and go")
    emitters: tuple[EmitterSwitch, ...] = spec((), doc="emitters switched on and off")
    labels: tuple[LabelDescription, ...] = spec(doc="what the camera is to tell, 1 or more")
    history_s: float = spec(
        1.0, unit="s", range=(0.0, 60.0), doc="measurements a speed label reads (the paper: 1 s)"
    )

    def __post_init__(self) -> None:
        _check_scene_file(self)
        movers = _unique("movers", self.movers)
        emitters: dict[str, object] = dict(_unique("emitters", self.emitters))
        if not self.labels:
            raise ValueError("labels = []: give at least one [[labels]] table")
        _unique("labels", self.labels, key="name")
        for i, label in enumerate(self.labels):
            _check_references(f"labels[{i}]", label, movers, emitters)


def _check_scene_file(config: MitsubaConfig) -> None:
    """Read the scene file's sha256 into ``scene_sha256``, or check it against the given one."""
    try:
        digest = hashlib.sha256(config.scene.read_bytes()).hexdigest()
    except OSError as err:
        raise ValueError(f"scene = '{config.scene}': cannot read it ({err.strerror})") from None
    if config.scene_sha256 and config.scene_sha256 != digest:
        raise ValueError(
            f"scene_sha256 = {config.scene_sha256!r}: the scene file now has sha256 {digest!r} "
            "(it was edited since; render into another --out)"
        )
    object.__setattr__(config, "scene_sha256", digest)


def _unique(field: str, items: tuple[T, ...], key: str = "id") -> dict[str, T]:
    """``{id: item}``; ValueError naming the first repeated id."""
    out: dict[str, T] = {}
    for i, item in enumerate(items):
        name = getattr(item, key)
        if name in out:
            raise ValueError(f"{field}[{i}].{key} = {name!r}: already used by another")
        out[name] = item
    return out


def _check_references(
    where: str, label: LabelDescription, movers: dict[str, Mover], emitters: dict[str, object]
) -> None:
    """ValueError where ``label`` names a mover or emitter the description lacks."""
    for i, name in enumerate(label.movers):
        if name not in movers:
            raise ValueError(f"{where}.movers[{i}] = {name!r}: {_none_such('mover', movers)}")
    for i, name in enumerate(label.emitters):
        if name not in emitters:
            raise ValueError(f"{where}.emitters[{i}] = {name!r}: {_none_such('emitter', emitters)}")
    if label.kind is LabelRule.EMITTER_ON and not emitters:
        raise ValueError(f"{where}: kind 'emitter_on' needs a switched emitter ([[emitters]])")
    if label.kind is LabelRule.COUNT_IN_REGION and not movers:
        raise ValueError(f"{where}: kind 'count_in_region' needs a mover ([[movers]])")
    if label.mover:
        if label.mover not in movers:
            raise ValueError(f"{where}.mover = {label.mover!r}: {_none_such('mover', movers)}")
        if movers[label.mover].switches:
            raise ValueError(
                f"{where}.mover = {label.mover!r}: it comes and goes (mean_present_s), so it "
                f"has no {label.kind.value} while away: use a mover that is always there"
            )


def _none_such(what: str, known: dict) -> str:
    return f"no {what} with this id in the description (have: {', '.join(known) or 'none'})"
