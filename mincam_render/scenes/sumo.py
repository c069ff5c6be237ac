"""Vehicle trajectories from Eclipse SUMO (``libsumo``) on a straight two-way road.

The network is a straight road along world +x, centred on x = 0, with
``lanes`` lanes in each direction (right-hand traffic: +x lanes at y < 0).
Optionally a signalised crossing (all directions red together, like a
pedestrian phase) sits at ``x = +/- signal_distance_m``, so each direction sees
a signal downstream of the camera (queues spill back at high demand) and one
upstream (platoons). Demand is Poisson (``period="exp(rate)"``) per direction
with a ``vTypeDistribution`` of vehicle types; SUMO's Krauss model with a
per-vehicle ``speedFactor ~ normc(mean, dev)`` gives realistic speed spread.

SUMO runs once, with a step of ``step_s`` (default 0.1 s; SUMO's clock has a
1-ms resolution, so 1/30 s cannot be its step), and vehicles within
``record_half_length_m`` of the camera are recorded at every step. Positions at
an arbitrary time are interpolated linearly between steps.

World frame: metres, +z up, +x along the road. Vehicle positions are the
*centre* of the vehicle's footprint (SUMO reports the front bumper).

Requires the ``traffic`` extra: ``pip install 'mincam_render[traffic]'``.
"""

from __future__ import annotations

import logging
import math
import os
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from mincam_render.core.seeds import stream_seed

log = logging.getLogger(__name__)

#: What to tell users who lack SUMO.
INSTALL_HINT = "pip install 'mincam_render[traffic]'"

#: Direction codes of :attr:`Trajectories.direction` (world +x / -x).
EASTBOUND, WESTBOUND = 0, 1


class MissingTrafficExtraError(ImportError):
    """Eclipse SUMO (the ``traffic`` extra) is not installed."""


def require_sumo() -> tuple[Any, Path]:
    """Import ``libsumo`` and find ``netconvert``.

    Returns:
        ``(libsumo module, path to the netconvert executable)``.

    Raises:
        MissingTrafficExtraError: SUMO is missing; the message names the extra.
    """
    try:
        import libsumo
    except ImportError as err:
        raise MissingTrafficExtraError(
            "the traffic scene family needs Eclipse SUMO (libsumo), which is not installed: "
            f"install the 'traffic' extra with {INSTALL_HINT}"
        ) from err
    try:
        import sumo  # the eclipse-sumo wheel, which ships netconvert

        netconvert = Path(sumo.SUMO_HOME) / "bin" / "netconvert"
    except ImportError as err:
        raise MissingTrafficExtraError(
            "the traffic scene family needs the eclipse-sumo package (netconvert): "
            f"install the 'traffic' extra with {INSTALL_HINT}"
        ) from err
    if not netconvert.is_file():
        raise MissingTrafficExtraError(
            f"netconvert not found at {netconvert}: "
            f"reinstall the 'traffic' extra with {INSTALL_HINT}"
        )
    return libsumo, netconvert


@dataclass(frozen=True, kw_only=True)
class SumoVehicleType:
    """A SUMO ``vType`` (SI units) and its share of the demand."""

    name: str
    vclass: str  # SUMO vehicle class: passenger, delivery, truck, bus
    share: float
    length_m: float
    width_m: float
    height_m: float
    max_speed_m_s: float
    speed_factor_mean: float
    speed_factor_dev: float
    accel_m_s2: float
    decel_m_s2: float
    sigma: float
    min_gap_m: float


@dataclass(frozen=True, kw_only=True)
class SumoRoad:
    """The simulated road and its demand (SI units)."""

    length_m: float
    lanes: int
    lane_width_m: float
    median_width_m: float
    speed_limit_m_s: float
    demand_veh_per_h: tuple[float, float]  # (+x, -x)
    vehicle_types: tuple[SumoVehicleType, ...]
    signal_distance_m: float
    signal_cycle_s: float  # 0 = no signals
    signal_green_fraction: float
    signal_yellow_s: float = 3.0


@dataclass
class Trajectories:
    """Recorded vehicle states at the SUMO steps (numpy).

    Step ``k`` is at sequence time ``k * step_s`` (the warm-up is before 0).
    Rows ``step_offsets[k]:step_offsets[k+1]`` of the flat arrays belong to step
    ``k``, sorted by vehicle index.

    Attributes:
        step_s: SUMO step (s).
        step_offsets: ``(steps + 1,)`` int64.
        vehicle: ``(R,)`` int32 vehicle index (departure order).
        center_m: ``(R, 2)`` float64 footprint centre x, y (m).
        yaw_rad: ``(R,)`` float64 heading, counter-clockwise from +x (rad).
        speed_m_s: ``(R,)`` float32 speed (m/s).
        vehicle_type: ``(V,)`` int32 index into the road's vehicle types, per vehicle.
        direction: ``(V,)`` int8 :data:`EASTBOUND` or :data:`WESTBOUND`, per vehicle.
        sumo_id: SUMO id per vehicle.
    """

    step_s: float
    step_offsets: np.ndarray
    vehicle: np.ndarray
    center_m: np.ndarray
    yaw_rad: np.ndarray
    speed_m_s: np.ndarray
    vehicle_type: np.ndarray
    direction: np.ndarray
    sumo_id: list[str]

    @property
    def num_steps(self) -> int:
        """Number of recorded steps."""
        return len(self.step_offsets) - 1

    def _step(self, k: int) -> slice:
        return slice(int(self.step_offsets[k]), int(self.step_offsets[k + 1]))

    def at(self, time_s: float) -> dict[str, np.ndarray]:
        """Vehicle states at ``time_s`` (s, >= 0), linearly interpolated between steps.

        A vehicle recorded at step ``k`` but not ``k + 1`` (it left the recorded
        region or the road) moves on at constant speed; one recorded only at
        ``k + 1`` (entering the region) is left out.

        Returns:
            dict with ``vehicle (N,)``, ``center_m (N, 2)``, ``yaw_rad (N,)``,
            ``speed_m_s (N,)``, sorted by vehicle index.
        """
        u = time_s / self.step_s
        k = min(max(int(math.floor(u + 1e-9)), 0), self.num_steps - 1)
        a = min(max(u - k, 0.0), 1.0)
        s0 = self._step(k)
        s1 = self._step(min(k + 1, self.num_steps - 1))
        v0, v1 = self.vehicle[s0], self.vehicle[s1]
        both, i0, i1 = np.intersect1d(v0, v1, assume_unique=True, return_indices=True)
        only0 = np.setdiff1d(np.arange(len(v0)), i0)
        c0, c1 = self.center_m[s0], self.center_m[s1]
        y0, y1 = self.yaw_rad[s0], self.yaw_rad[s1]
        sp0, sp1 = self.speed_m_s[s0], self.speed_m_s[s1]
        dyaw = (y1[i1] - y0[i0] + np.pi) % (2 * np.pi) - np.pi
        # leaving the recorded region: extrapolate along the heading at constant speed
        ahead = (a * self.step_s * sp0[only0])[:, None] * np.stack(
            [np.cos(y0[only0]), np.sin(y0[only0])], axis=1
        )
        vehicle = np.concatenate([both, v0[only0]])
        center = np.concatenate([(1 - a) * c0[i0] + a * c1[i1], c0[only0] + ahead])
        yaw = np.concatenate([y0[i0] + a * dyaw, y0[only0]])
        speed = np.concatenate([(1 - a) * sp0[i0] + a * sp1[i1], sp0[only0]])
        order = np.argsort(vehicle, kind="stable")
        return {
            "vehicle": vehicle[order].astype(np.int32),
            "center_m": center[order],
            "yaw_rad": yaw[order],
            "speed_m_s": speed[order].astype(np.float32),
        }


def _write_network(road: SumoRoad, workdir: Path, netconvert: Path) -> Path:
    half = road.length_m / 2
    xs = [-half, half]
    signals = road.signal_cycle_s > 0
    if signals:
        xs = [-half, -road.signal_distance_m, road.signal_distance_m, half]
    names = [f"n{i}" for i in range(len(xs))]
    nodes = "\n".join(
        f'  <node id="{n}" x="{x:.3f}" y="0" type="'
        f'{"traffic_light" if signals and 0 < i < len(xs) - 1 else "dead_end"}"/>'
        for i, (n, x) in enumerate(zip(names, xs, strict=True))
    )
    attrs = (
        f'numLanes="{road.lanes}" speed="{road.speed_limit_m_s:.4f}" '
        f'width="{road.lane_width_m:.4f}"'
    )
    edges = []
    for i in range(len(xs) - 1):
        edges.append(f'  <edge id="e{i}" from="{names[i]}" to="{names[i + 1]}" {attrs}/>')
        edges.append(f'  <edge id="w{i}" from="{names[i + 1]}" to="{names[i]}" {attrs}/>')
    (workdir / "road.nod.xml").write_text(f"<nodes>\n{nodes}\n</nodes>\n")
    (workdir / "road.edg.xml").write_text("<edges>\n" + "\n".join(edges) + "\n</edges>\n")
    net = workdir / "road.net.xml"
    cmd = [
        str(netconvert),
        "--node-files", str(workdir / "road.nod.xml"),
        "--edge-files", str(workdir / "road.edg.xml"),
        "--output-file", str(net),
        "--offset.disable-normalization", "true",
        "--no-turnarounds", "true",
        "--xml-validation", "never",
    ]  # fmt: skip
    env = dict(os.environ)
    env.setdefault("SUMO_HOME", str(netconvert.parent.parent))
    res = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    if res.returncode != 0 or not net.is_file():
        raise RuntimeError(f"netconvert failed ({res.returncode}): {res.stderr.strip()[-500:]}")
    return net


def _write_routes(road: SumoRoad, workdir: Path, end_s: float) -> Path:
    n_edges = 3 if road.signal_cycle_s > 0 else 1
    east = " ".join(f"e{i}" for i in range(n_edges))
    west = " ".join(f"w{i}" for i in reversed(range(n_edges)))
    total = sum(t.share for t in road.vehicle_types)
    vtypes = []
    for t in road.vehicle_types:
        if t.share <= 0:
            continue
        sf = f"normc({t.speed_factor_mean:.4f},{t.speed_factor_dev:.4f},0.2,2.0)"
        vtypes.append(
            f'    <vType id="{t.name}" vClass="{t.vclass}" probability="{t.share / total:.6f}" '
            f'length="{t.length_m:.3f}" width="{t.width_m:.3f}" height="{t.height_m:.3f}" '
            f'maxSpeed="{t.max_speed_m_s:.3f}" speedFactor="{sf}" accel="{t.accel_m_s2:.3f}" '
            f'decel="{t.decel_m_s2:.3f}" sigma="{t.sigma:.3f}" minGap="{t.min_gap_m:.3f}"/>'
        )
    flows = []
    for name, route, rate_h in (("east", "r_east", road.demand_veh_per_h[0]),
                                ("west", "r_west", road.demand_veh_per_h[1])):  # fmt: skip
        if rate_h > 0:
            flows.append(
                f'  <flow id="{name}" type="mix" route="{route}" begin="0" end="{end_s:.3f}" '
                f'period="exp({rate_h / 3600.0:.8f})" departLane="free" departSpeed="desired"/>'
            )
    text = (
        "<routes>\n"
        '  <vTypeDistribution id="mix">\n' + "\n".join(vtypes) + "\n  </vTypeDistribution>\n"
        f'  <route id="r_east" edges="{east}"/>\n'
        f'  <route id="r_west" edges="{west}"/>\n' + "\n".join(flows) + "\n</routes>\n"
    )
    path = workdir / "road.rou.xml"
    path.write_text(text)
    return path


def _signal_state(time_s: float, road: SumoRoad, offset_s: float) -> str:
    """'G', 'y' or 'r' for all links of a signal at absolute SUMO time ``time_s``."""
    phase = (time_s + offset_s) % road.signal_cycle_s
    green = road.signal_green_fraction * road.signal_cycle_s
    if phase < green:
        return "G"
    if phase < green + road.signal_yellow_s:
        return "y"
    return "r"


#: SUMO's ``--seed`` is a C ``int``: seeds from 0 to this are passed as they are.
SUMO_MAX_SEED = 2**31 - 1


def sumo_seed(seed: int) -> int:
    """SUMO's ``--seed`` for a scene seed >= 0: the seed itself up to :data:`SUMO_MAX_SEED`.

    Larger seeds (a study's episode seeds lie in [0, 2^63)) are folded into
    range through their own stream (:func:`~mincam_render.core.seeds.stream_seed`),
    so distinct episodes keep distinct traffic; small seeds keep the traffic
    they always had.
    """
    if seed < 0:
        raise ValueError(f"seed = {seed}: allowed an integer >= 0")
    if seed <= SUMO_MAX_SEED:
        return int(seed)
    return stream_seed(int(seed), "sumo") % (SUMO_MAX_SEED + 1)


def _sumo_args(net: Path, routes: Path, step_s: float, seed: int) -> list[str]:
    """Command line of a SUMO run on ``net`` with demand ``routes`` (step in s, seed >= 0)."""
    return [
        "sumo",
        "--net-file", str(net),
        "--route-files", str(routes),
        "--step-length", f"{step_s:.3f}",
        "--seed", str(sumo_seed(seed)),
        "--step-method.ballistic", "true",  # position advances by the mean speed of a step
        "--lanechange.duration", "2",  # lateral motion over 2 s, not a jump
        "--time-to-teleport", "-1",  # no teleports out of jams
        "--xml-validation", "never",
        "--no-step-log", "true",
        "--no-warnings", "true",
        "--duration-log.disable", "true",
    ]  # fmt: skip


class _SignalController:
    """Sets every traffic light of a running SUMO to :func:`_signal_state` at each step."""

    def __init__(self, libsumo: Any, road: SumoRoad) -> None:
        self._libsumo = libsumo
        self._road = road
        self._tls = list(libsumo.trafficlight.getIDList())
        self._links = {t: len(libsumo.trafficlight.getRedYellowGreenState(t)) for t in self._tls}
        # the two signals are half a cycle apart so platoons are not synchronous
        self._offset_s = {t: 0.5 * road.signal_cycle_s * i for i, t in enumerate(sorted(self._tls))}

    def set(self, time_s: float) -> None:
        """Set the signals' states for SUMO time ``time_s`` (s)."""
        for t in self._tls:
            self._libsumo.trafficlight.setRedYellowGreenState(
                t, _signal_state(time_s, self._road, self._offset_s[t]) * self._links[t]
            )


class _TrackRecorder:
    """Vehicles of a running SUMO, numbered in departure order, and their states per step."""

    def __init__(self, libsumo: Any, road: SumoRoad, record_half_length_m: float) -> None:
        self._libsumo = libsumo
        self._road = road
        self._half_length_m = record_half_length_m
        self._type_index = {t.name: i for i, t in enumerate(road.vehicle_types)}
        self._lengths_m = np.array([t.length_m for t in road.vehicle_types])
        self._vars = (libsumo.VAR_POSITION, libsumo.VAR_ANGLE, libsumo.VAR_SPEED)
        self.index_of: dict[str, int] = {}
        self.vtype: list[int] = []
        self.direction: list[int] = []
        self.offsets = [0]
        self.rows: dict[str, list[np.ndarray]] = {
            "vehicle": [],
            "center": [],
            "yaw": [],
            "speed": [],
        }

    def add_departed(self) -> None:
        """Number the vehicles that departed in the last step and subscribe to their states."""
        for vid in self._libsumo.simulation.getDepartedIDList():
            self.index_of[vid] = len(self.vtype)
            self.vtype.append(self._type_index[self._libsumo.vehicle.getTypeID(vid)])
            self.direction.append(EASTBOUND if vid.startswith("east") else WESTBOUND)
            self._libsumo.vehicle.subscribe(vid, self._vars)

    def record_step(self) -> None:
        """Append the states of the vehicles within the recorded length, sorted by index."""
        res = self._libsumo.vehicle.getAllSubscriptionResults()
        ids = [vid for vid in res if vid in self.index_of]
        if not ids:
            self.offsets.append(self.offsets[-1])
            return
        idx = np.array([self.index_of[v] for v in ids], dtype=np.int32)
        front = np.array([res[v][self._vars[0]] for v in ids], dtype=np.float64)
        angle = np.array([res[v][self._vars[1]] for v in ids], dtype=np.float64)
        speed = np.array([res[v][self._vars[2]] for v in ids], dtype=np.float32)
        yaw, center = self._footprint(idx, front, angle)
        keep = np.abs(center[:, 0]) < self._half_length_m
        order = np.argsort(idx[keep], kind="stable")
        self.rows["vehicle"].append(idx[keep][order])
        self.rows["center"].append(center[keep][order])
        self.rows["yaw"].append(yaw[keep][order])
        self.rows["speed"].append(speed[keep][order])
        self.offsets.append(self.offsets[-1] + int(keep.sum()))

    def _footprint(
        self, idx: np.ndarray, front: np.ndarray, angle: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Yaw (rad, ccw from +x) and footprint centre ``[vehicle, xy]`` (m) of SUMO's states.

        Args:
            idx: ``(n,)`` vehicle indices.
            front: ``(n, 2)`` front-bumper positions in SUMO's network (m).
            angle: ``(n,)`` SUMO angles (deg).
        """
        # SUMO angle: degrees clockwise from north (+y)
        yaw = np.radians(90.0 - angle)
        half_len = 0.5 * self._lengths_m[np.asarray(self.vtype)[idx]]
        center = front - half_len[:, None] * np.stack([np.cos(yaw), np.sin(yaw)], 1)
        east = np.asarray(self.direction)[idx] == EASTBOUND
        center[:, 1] += np.where(east, -0.5, 0.5) * self._road.median_width_m
        return yaw, center

    def trajectories(self, step_s: float) -> Trajectories:
        """The recorded steps (``step_s`` in s) as :class:`Trajectories`."""

        def cat(
            parts: list[np.ndarray], dtype: npt.DTypeLike, shape: tuple[int, ...] = ()
        ) -> np.ndarray:
            return np.concatenate(parts).astype(dtype) if parts else np.zeros((0, *shape), dtype)

        return Trajectories(
            step_s=step_s,
            step_offsets=np.asarray(self.offsets, dtype=np.int64),
            vehicle=cat(self.rows["vehicle"], np.int32),
            center_m=cat(self.rows["center"], np.float64, (2,)),
            yaw_rad=cat(self.rows["yaw"], np.float64),
            speed_m_s=cat(self.rows["speed"], np.float32),
            vehicle_type=np.asarray(self.vtype, dtype=np.int32),
            direction=np.asarray(self.direction, dtype=np.int8),
            sumo_id=sorted(self.index_of, key=self.index_of.__getitem__),
        )


def simulate(
    road: SumoRoad,
    *,
    seed: int,
    duration_s: float,
    warmup_s: float,
    step_s: float,
    record_half_length_m: float,
) -> Trajectories:
    """Run SUMO once and record vehicles near the camera.

    Args:
        road: network, demand and vehicle types.
        seed: the scene's seed, >= 0 (SUMO's ``--seed`` is :func:`sumo_seed` of it).
        duration_s: recorded time after the warm-up (s).
        warmup_s: simulated time before the first recorded step (s), so the
            road is populated and signal queues are established.
        step_s: SUMO step (s), a multiple of 1 ms.
        record_half_length_m: record vehicles whose centre has ``|x|`` below this (m).

    Returns:
        The recorded trajectories; step 0 is at ``warmup_s`` of SUMO time.

    Raises:
        MissingTrafficExtraError: SUMO is not installed.
        RuntimeError: netconvert or SUMO failed.
    """
    libsumo, netconvert = require_sumo()
    steps = int(math.ceil(duration_s / step_s)) + 2
    end_s = warmup_s + steps * step_s + 1.0
    recorder = _TrackRecorder(libsumo, road, record_half_length_m)
    with tempfile.TemporaryDirectory(prefix="mincam_sumo_") as tmp:
        work = Path(tmp)
        net = _write_network(road, work, netconvert)
        routes = _write_routes(road, work, end_s)
        libsumo.start(_sumo_args(net, routes, step_s, seed))
        try:
            _run_steps(
                libsumo,
                _SignalController(libsumo, road),
                recorder,
                steps=steps,
                warm=int(round(warmup_s / step_s)),
                step_s=step_s,
            )
        finally:
            libsumo.close()
    return recorder.trajectories(step_s)


def _run_steps(
    libsumo: Any,
    signals: _SignalController,
    recorder: _TrackRecorder,
    *,
    steps: int,
    warm: int,
    step_s: float,
) -> None:
    """Step a running SUMO ``warm + steps`` times, recording the last ``steps + 1`` states.

    Args:
        libsumo: the started ``libsumo`` module.
        signals: sets the traffic lights before each step.
        recorder: numbers departed vehicles and records their states.
        steps: recorded steps after the warm-up.
        warm: warm-up steps.
        step_s: SUMO step (s).
    """
    t_sim = 0.0
    for k in range(warm + steps):
        signals.set(t_sim)
        libsumo.simulationStep()
        t_sim = (k + 1) * step_s
        recorder.add_departed()
        if k + 1 >= warm:
            recorder.record_step()
