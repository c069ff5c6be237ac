"""What the main job compares: camera designs and the comparison's configuration, as data.

No PyTorch or Mitsuba import, so the command line shows these defaults at once.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeVar

from mincam_render.core.checks import check_int, check_number
from mincam_render.learn.train_config import HeadKind, MaskReference, TrainConfig


class Protocol(enum.Enum):
    """Which labels one set of masks is trained for.

    * ``PER_TASK``: the paper's (Sec. 7, "two for each task"): every design is
      trained once per task of the family (:func:`~mincam_render.core.labels.label_tasks`;
      workspace: the people count, the zones, the door), each camera with the
      design's pixel budget and early stopping on its own task's loss; a camera
      for every task is the union of their pixels.
    * ``JOINT``: one camera for every label (the losses summed).
    """

    PER_TASK = "per-task"
    JOINT = "joint"


_E = TypeVar("_E", bound=enum.Enum)


def _enum_of_json(kind: type[_E], text: str) -> _E:
    """``kind``'s member of ``text``: its value, or ``"Kind.NAME"`` (its ``str``)."""
    prefix = f"{kind.__name__}."
    if text.startswith(prefix) and text[len(prefix) :] in kind.__members__:
        return kind[text[len(prefix) :]]
    try:
        return kind(text)
    except ValueError:
        allowed = ", ".join(repr(m.value) for m in kind)
        raise ValueError(f"{kind.__name__} = {text!r}: allowed {allowed}") from None


def designs_by_name(records: Sequence[Mapping[str, Any]]) -> dict[str, Design]:
    """``{name: design}`` of a result's ``config`` designs (:meth:`Design.from_json`)."""
    designs = (Design.from_json(r) for r in records)
    return {d.name: d for d in designs}


@dataclass(frozen=True)
class Design:
    """One camera design: a minimalist camera of ``pixels`` or a baseline of ``grid``.

    Args:
        pixels: freeform pixels (minimalist camera), or None for a baseline.
        grid: ``(rows, cols)`` of a conventional camera, or None.
        sensor_model: train the minimalist camera with the detector model (noise,
            saturation); False is the paper's supplement-A ablation: masks trained
            without the model, then frozen while a fresh head is trained with it,
            and tested with it.
        head: the inference network (replaces the recipe's ``TrainConfig.head``).
        privacy_weight: masks trained with the adversarial privacy term of this
            weight (replaces the recipe's ``TrainConfig.privacy_weight``); 0: the
            task alone. A minimalist camera's option only.
        reference: the masks are this reference's, fitted on the training split
            (:class:`~mincam_render.learn.reference_masks.MaskReference`: principal
            components, partial least squares, a distilled full-resolution
            network), made printable and frozen; only the head trains. None:
            masks learned end to end. A minimalist camera's option only.
        tuned: with ``reference``, the masks start from it and train end to end.
    """

    pixels: int | None = None
    grid: tuple[int, int] | None = None
    sensor_model: bool = True
    head: HeadKind = HeadKind.MLP
    privacy_weight: float = 0.0
    reference: MaskReference | None = None
    tuned: bool = False

    def __post_init__(self) -> None:
        if (self.pixels is None) == (self.grid is None):
            raise ValueError(f"{self}: give exactly one of pixels (mincam) or grid (baseline)")
        if self.pixels is not None:
            check_int("Design.pixels", self.pixels, 1)
        if self.grid is not None:
            object.__setattr__(self, "grid", (int(self.grid[0]), int(self.grid[1])))
        object.__setattr__(self, "head", HeadKind(self.head))
        check_number("Design.privacy_weight", self.privacy_weight, 0, 1e3, numpy=True)
        if self.privacy_weight and self.grid is not None:
            raise ValueError(f"{self}: a privacy weight trains masks; a baseline has none")
        if self.reference is not None:
            object.__setattr__(self, "reference", MaskReference(self.reference))
            if self.grid is not None:
                raise ValueError(f"{self}: reference masks are a minimalist camera's")
        elif self.tuned:
            raise ValueError(f"{self}: tuned starts from reference masks; give a reference")

    @property
    def name(self) -> str:
        """``mincam-8px``, ``mincam-8px-nosensor``, ``baseline-8x8``; ``-tcn`` for that head.

        A privacy weight of 1 adds ``-private1`` (before the head's suffix), a
        reference ``-pca`` (``-pca-tuned`` when trained from it).
        """
        suffix = "" if self.head is HeadKind.MLP else f"-{self.head.value}"
        if self.grid is not None:
            return f"baseline-{self.grid[0]}x{self.grid[1]}{suffix}"
        private = f"-private{self.privacy_weight:g}" if self.privacy_weight else ""
        sensor = "" if self.sensor_model else "-nosensor"
        ref = "" if self.reference is None else f"-{self.reference.value}"
        ref += "-tuned" if self.tuned else ""
        return f"mincam-{self.pixels}px{sensor}{ref}{private}{suffix}"

    @property
    def is_mincam(self) -> bool:
        """A minimalist camera (it has masks to keep)."""
        return self.pixels is not None

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Design:
        """The design of its JSON form in a result's ``config`` (``dataclasses.asdict``).

        Enums there are their values, or their ``str`` (``"HeadKind.MLP"``) as
        ``json.dumps(..., default=str)`` wrote them; fields a result from before
        them lacks take their defaults.

        Raises:
            ValueError: an unknown head or reference, or an invalid design.
        """
        ref = d.get("reference")
        return cls(
            pixels=d.get("pixels"),
            grid=None if d.get("grid") is None else tuple(d["grid"]),
            sensor_model=bool(d.get("sensor_model", True)),
            head=_enum_of_json(HeadKind, d.get("head", HeadKind.MLP.value)),
            privacy_weight=float(d.get("privacy_weight", 0.0)),
            reference=None if ref is None else _enum_of_json(MaskReference, ref),
            tuned=bool(d.get("tuned", False)),
        )


@dataclass(frozen=True, kw_only=True)
class ComparisonConfig:
    """What the main job renders and trains.

    Args:
        family: scene family name or description (.toml).
        seed: root seed of every episode and training seed.
        fps: frame rate of the episodes (1/s); 2 fps: 1,200 frames = 10 min of activity.
        overrides: values replacing the scene description's in every episode (nested
            as in the TOML, e.g. ``{"camera": {"detectors": 16}}``; ``fps`` is its own
            field).
        light_scale: every emitter's radiance times this factor (> 0), applied to
            the rendered episodes (transport is linear in it), so light levels
            share one render.
        train_episodes: training episodes (a temporal task's windows stay within one).
        train_frames: frames of each training episode.
        val_episodes: validation episodes (other scene seeds), pooled for early
            stopping and for choosing the kept run: one episode is a poor guide
            (its people, schedule and daylight are one draw).
        val_frames: frames of each validation episode.
        test_frames: frames of each test episode.
        test_episodes: number of test episodes (>= 2 for an interval over episodes).
        seeds: training seeds per design (>= 2 for an interval over seeds).
        designs: the camera designs (each once); with two, the verdict compares them.
        train: the training recipe (its ``seed`` is replaced per training seed, its
            ``head`` by each design's).
        fidelity: :class:`RenderRequest` fidelity fields (``{}`` = measured, auto).
        mask_res: mask texels per side rendered (None: the family camera's); a
            baseline grid can be at most this fine (64 x 64 needs 64).
        protocol: per-task cameras (the paper's) or one joint camera (:class:`Protocol`).
        oracle_background: an oracle, not a camera: every frame's converged
            background (the empty room with the frame's lights and daylight) is
            replaced by one fixed background (the first episode's mean), so the
            cameras see the people and the door (with their render noise) in a
            room whose light never changes. Bounds what knowing the background
            exactly would give (differentially rendered families).
        tasks: under ``PER_TASK``, the tasks trained (names of
            :func:`~mincam_render.core.labels.label_tasks`, e.g. ``("people_count",)``);
            empty: every task of the family.
    """

    family: str = "workspace"
    seed: int = 0
    fps: float = 2.0
    overrides: Mapping[str, Any] = field(default_factory=dict)
    light_scale: float = 1.0
    train_episodes: int = 2
    train_frames: int = 1200
    val_episodes: int = 3
    val_frames: int = 600
    test_frames: int = 600
    test_episodes: int = 3
    seeds: int = 3
    designs: tuple[Design, ...] = (Design(pixels=8), Design(grid=(8, 8)))
    train: TrainConfig = TrainConfig()
    fidelity: Mapping[str, Any] = field(default_factory=dict)
    mask_res: int | None = None
    protocol: Protocol = Protocol.PER_TASK
    tasks: tuple[str, ...] = ()
    oracle_background: bool = False

    def __post_init__(self) -> None:
        try:
            object.__setattr__(self, "protocol", Protocol(self.protocol))
        except ValueError:
            allowed = [p.value for p in Protocol]
            raise ValueError(f"protocol = {self.protocol!r}: allowed {allowed}") from None
        object.__setattr__(self, "tasks", tuple(self.tasks))
        if self.tasks and self.protocol is Protocol.JOINT:
            raise ValueError(f"tasks {list(self.tasks)}: a joint camera trains every label")
        for name in ("train_frames", "val_frames", "test_frames"):
            check_int(name, getattr(self, name), 30, unit="frames")
        for name in ("train_episodes", "val_episodes", "test_episodes", "seeds"):
            check_int(name, getattr(self, name), 1)
        check_number("light_scale", self.light_scale, 0, lo_open=True, numpy=True)
        if "fps" in self.overrides:
            raise ValueError("overrides: give the frame rate as fps, not as an override")
        self._check_grids()
        names = [d.name for d in self.designs]
        if not names or len(set(names)) != len(names):
            raise ValueError(f"designs {names}: need at least one, each once")

    def _check_grids(self) -> None:
        """Refuse, before any render, a baseline grid finer than the rendered ``mask_res``."""
        if self.mask_res is None:
            return
        check_int("mask_res", self.mask_res, 1, 4096)
        for d in self.designs:
            if d.grid is not None and max(d.grid) > self.mask_res:
                raise ValueError(
                    f"{d.name}: a {d.grid[0]}x{d.grid[1]} baseline needs at least "
                    f"{max(d.grid)} texels per side; mask_res = {self.mask_res}"
                )

    def task_labels(self, tasks: Mapping[str, tuple[str, ...]]) -> dict[str, tuple[str, ...]]:
        """``{task: labels}`` trained, from the family's ``tasks`` (:func:`label_tasks`).

        ``JOINT``: one task, ``"joint"``, of every label. ``PER_TASK``: the
        family's tasks (or those of :attr:`tasks`).

        Raises:
            ValueError: :attr:`tasks` names a task the family does not have.
        """
        if self.protocol is Protocol.JOINT:
            return {"joint": tuple(label for names in tasks.values() for label in names)}
        unknown = [t for t in self.tasks if t not in tasks]
        if unknown:
            raise ValueError(f"tasks {unknown}: the family's tasks are {list(tasks)}")
        return {t: names for t, names in tasks.items() if not self.tasks or t in self.tasks}
