"""Where the movers are and which emitters are on, frame by frame (numpy, simulated once).

Each mover and each switched emitter draws from its own random stream
(``core.seeds.stream_seed`` of the sequence's seed and its id), so adding one
changes no other's trajectory. Frames are the times ``i / fps``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mincam_render.core.seeds import stream_seed
from mincam_render.scenes.declarative.config import Box, EmitterSwitch, Mover
from mincam_render.scenes.indoor.motion import switching_process


@dataclass(frozen=True)
class MoverTrack:
    """A mover per frame: ``position_m[frame, 3]`` of its reference point, ``present[frame]``.

    ``speed_m_s[frame]``: the distance its reference point covers between
    consecutive frames times the frame rate (from frame 0 to 1 for frame 0).
    """

    position_m: np.ndarray
    present: np.ndarray
    speed_m_s: np.ndarray


def simulate_mover(mover: Mover, *, seed: int, num_frames: int, fps: float) -> MoverTrack:
    """The track of ``mover`` over ``num_frames`` frames at ``fps``."""
    rng = np.random.default_rng(stream_seed(seed, f"declarative/mover/{mover.id}"))
    present = (
        switching_process(rng, num_frames, fps, mover.mean_present_s, mover.mean_absent_s)
        if mover.switches
        else np.ones(num_frames, dtype=bool)
    )
    if mover.region is not None:
        position = _in_region(mover.region, mover, rng, present, fps)
    else:
        position = _along_path(mover, rng, present, fps)
    step = np.linalg.norm(np.diff(position, axis=0), axis=1) * fps
    speed = np.concatenate([step[:1], step]) if num_frames > 1 else np.zeros(1)
    return MoverTrack(position_m=position, present=present, speed_m_s=speed)


def simulate_switches(
    emitters: tuple[EmitterSwitch, ...], *, seed: int, num_frames: int, fps: float
) -> np.ndarray:
    """``on[frame, emitter]`` (bool) of the switched emitters, in description order."""
    states = [
        switching_process(
            np.random.default_rng(stream_seed(seed, f"declarative/emitter/{e.id}")),
            num_frames,
            fps,
            e.mean_on_s,
            e.mean_off_s,
        )
        for e in emitters
    ]
    return np.stack(states, axis=1) if states else np.zeros((num_frames, 0), dtype=bool)


def _in_region(
    region: Box, mover: Mover, rng: np.random.Generator, present: np.ndarray, fps: float
) -> np.ndarray:
    """Random waypoints: appear anywhere in the region, walk to random targets, pause there.

    Away, it stays where it was; it comes back anywhere.
    """
    lo, hi = np.asarray(region.min_m), np.asarray(region.max_m)
    out = np.empty((len(present), 3))
    walker = _Walker(lo, hi, mover, rng)
    for i, shown in enumerate(present):
        if shown and (i == 0 or not present[i - 1]):
            walker.appear()
        elif shown:
            walker.advance(1.0 / fps)
        out[i] = walker.position
    return out


class _Walker:
    """A point walking between uniformly random targets of a box, at a speed drawn per leg."""

    def __init__(
        self, lo: np.ndarray, hi: np.ndarray, mover: Mover, rng: np.random.Generator
    ) -> None:
        self.lo, self.hi, self.mover, self.rng = lo, hi, mover, rng
        self.position = rng.uniform(lo, hi)
        self._new_leg()

    def appear(self) -> None:
        """Place it anew, anywhere in the box."""
        self.position = self.rng.uniform(self.lo, self.hi)
        self._new_leg()

    def _new_leg(self) -> None:
        self.target = self.rng.uniform(self.lo, self.hi)
        self.speed = float(self.rng.uniform(*self.mover.speed_m_s))
        self.pause_left = 0.0

    def advance(self, dt: float) -> None:
        """Move for ``dt`` seconds: pause, walk, and take new legs as targets are reached."""
        while dt > 0 and self.speed > 0:
            if self.pause_left > 0:
                used = min(dt, self.pause_left)
                self.pause_left, dt = self.pause_left - used, dt - used
                continue
            gap = self.target - self.position
            distance = float(np.linalg.norm(gap))
            if distance > self.speed * dt:
                self.position = self.position + gap * (self.speed * dt / distance)
                return
            self.position, dt = self.target, dt - distance / self.speed
            pause = float(self.rng.uniform(*self.mover.pause_s))
            self._new_leg()
            self.pause_left = pause
            if distance == 0 and pause == 0:  # a box of no extent: nowhere else to go
                return


def _along_path(
    mover: Mover, rng: np.random.Generator, present: np.ndarray, fps: float
) -> np.ndarray:
    """A closed loop through the waypoints, from a random start, at a speed per appearance."""
    points = np.asarray(mover.path, dtype=np.float64)
    loop = np.vstack([points, points[:1]])
    lengths = np.linalg.norm(np.diff(loop, axis=0), axis=1)
    total = float(lengths.sum())
    ends = np.concatenate([[0.0], np.cumsum(lengths)])
    arc = rng.uniform(0.0, total)
    speed = rng.uniform(*mover.speed_m_s)
    out = np.empty((len(present), 3))
    for i, shown in enumerate(present):
        if i > 0:
            if shown and not present[i - 1]:
                speed = rng.uniform(*mover.speed_m_s)
            arc = (arc + speed / fps) % total if total > 0 else 0.0
        leg = min(int(np.searchsorted(ends, arc, side="right")) - 1, len(lengths) - 1)
        frac = (arc - ends[leg]) / lengths[leg] if lengths[leg] > 0 else 0.0
        out[i] = loop[leg] + frac * (loop[leg + 1] - loop[leg])
    return out
