"""How things move: paths around furniture, people's visits, the door, switched lights.

Everything is simulated once from a seeded ``np.random.Generator`` (numpy), so a
frame's state is a pure function of its index.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import Any

import networkx as nx
import numpy as np

from mincam_render.scenes.indoor.config import FurnitureConfig, PeopleConfig, RoomConfig
from mincam_render.scenes.indoor.door import Door
from mincam_render.scenes.indoor.people import Appearance, Pose, draw_roster

#: Navigation grid cell (m) and the clearance kept from walls and furniture (m).
NAV_CELL_M = 0.1
NAV_CLEARANCE_M = 0.3
#: Rates of the people's motion: turning (rad/s), sitting down/standing up (1/s),
#: starting/stopping the gait (1/s); stride of a full gait cycle per metre of height.
TURN_RATE_RAD_S = 5.0
SIT_RATE_PER_S = 1.0
GAIT_RATE_PER_S = 3.0
CYCLE_LENGTH_PER_HEIGHT = 0.8


def walk_graph(free: np.ndarray) -> nx.Graph:
    """8-connected graph of the free cells ``free[iy, ix]`` (bool).

    Nodes are cells ``(iy, ix)``; edges join free neighbours, ``weight`` 1 cell
    between side neighbours and sqrt(2) cells between diagonal ones.
    """
    graph = nx.Graph()
    graph.add_nodes_from(map(tuple, np.argwhere(free).tolist()))
    ny, nx_ = free.shape
    for dy, dx in ((0, 1), (1, 0), (1, 1), (1, -1)):
        x0, x1 = max(0, -dx), nx_ - max(0, dx)
        both = free[: ny - dy, x0:x1] & free[dy:, x0 + dx : x1 + dx]
        iy, ix = np.nonzero(both)
        ix = ix + x0
        w = math.hypot(dy, dx)
        graph.add_weighted_edges_from(
            ((y, x), (y + dy, x + dx), w) for y, x in zip(iy.tolist(), ix.tolist(), strict=True)
        )
    return graph


class NavGrid:
    """Free floor cells (``NAV_CELL_M``) at ``NAV_CLEARANCE_M`` from walls and obstacles."""

    def __init__(self, room: RoomConfig, obstacles: list[FurnitureConfig]) -> None:
        w, d, _ = room.size_m
        self.nx, self.ny = int(math.ceil(w / NAV_CELL_M)), int(math.ceil(d / NAV_CELL_M))
        xs = (np.arange(self.nx) + 0.5) * NAV_CELL_M
        ys = (np.arange(self.ny) + 0.5) * NAV_CELL_M
        gx, gy = np.meshgrid(xs, ys)  # [iy, ix]
        c = NAV_CLEARANCE_M
        free = (gx > c) & (gx < w - c) & (gy > c) & (gy < d - c)
        for f in obstacles:
            dd, ww, _ = f.size
            a = math.radians(f.rotation_deg)
            rx = (gx - f.position_m[0]) * math.cos(a) + (gy - f.position_m[1]) * math.sin(a)
            ry = -(gx - f.position_m[0]) * math.sin(a) + (gy - f.position_m[1]) * math.cos(a)
            free &= ~((np.abs(rx) < dd / 2 + c) & (np.abs(ry) < ww / 2 + c))
        self.free = free
        self.free_cells = np.argwhere(free)  # (iy, ix)
        if len(self.free_cells) == 0:
            raise ValueError("furniture: no free floor left to walk on")
        self.graph = walk_graph(free)

    def cell(self, p: np.ndarray) -> tuple[int, int]:
        ix = min(max(int(p[0] / NAV_CELL_M), 0), self.nx - 1)
        iy = min(max(int(p[1] / NAV_CELL_M), 0), self.ny - 1)
        return iy, ix

    def point(self, c: tuple[int, int] | np.ndarray) -> np.ndarray:
        return (np.array([c[1], c[0]], dtype=np.float64) + 0.5) * NAV_CELL_M

    def nearest_free(self, p: np.ndarray) -> tuple[int, int]:
        iy, ix = self.cell(p)
        if self.free[iy, ix]:
            return iy, ix
        d = np.abs(self.free_cells - [iy, ix]).sum(axis=1)
        iy, ix = self.free_cells[int(np.argmin(d))]
        return int(iy), int(ix)

    def random_point(self, rng: np.random.Generator) -> np.ndarray:
        c = self.free_cells[rng.integers(len(self.free_cells))]
        return self.point(c) + rng.uniform(-0.3, 0.3, 2) * NAV_CELL_M

    def _clear(self, a: np.ndarray, b: np.ndarray) -> bool:
        n = int(np.linalg.norm(b - a) / (0.5 * NAV_CELL_M)) + 2
        for t in np.linspace(0, 1, n):
            iy, ix = self.cell(a + t * (b - a))
            if not self.free[iy, ix]:
                return False
        return True

    def cell_path(self, start: tuple[int, int], goal: tuple[int, int]) -> list[tuple[int, int]]:
        """Shortest 8-connected path of free cells ``(iy, ix)`` from ``start`` to ``goal``.

        ``networkx.astar_path`` on :func:`walk_graph` with the Euclidean distance
        (cells) as heuristic, so the path is a shortest one.

        Raises:
            ValueError: no free path joins the two cells (furniture closes the way).
        """
        try:
            return nx.astar_path(
                self.graph, start, goal, heuristic=lambda u, v: math.dist(u, v), weight="weight"
            )
        except nx.NetworkXNoPath:
            a, b = (np.round(self.point(c), 2).tolist() for c in (start, goal))
            raise ValueError(
                f"furniture: no walkable path from {a} m to {b} m (the free floor at "
                f"{NAV_CLEARANCE_M} m clearance is split); move the furniture apart"
            ) from None

    def plan(self, a: np.ndarray, b: np.ndarray) -> list[np.ndarray]:
        """Waypoints from ``a`` to ``b`` (x, y, m) around obstacles.

        :meth:`cell_path` between the free cells nearest ``a`` and ``b``,
        string-pulled: a cell is kept only where the straight line to a later one
        would cross an obstacle.

        Raises:
            ValueError: no free path joins the two cells.
        """
        a, b = np.asarray(a, float), np.asarray(b, float)
        cells = self.cell_path(self.nearest_free(a), self.nearest_free(b))
        pts = [self.point(c) for c in cells]
        # string-pulling: keep a point only when the straight line would cross an obstacle
        smooth = [pts[0]]
        i = 0
        while i < len(pts) - 1:
            j = len(pts) - 1
            while j > i + 1 and not self._clear(pts[i], pts[j]):
                j -= 1
            smooth.append(pts[j])
            i = j
        return [a, *smooth, b]


def switching_process(
    rng: np.random.Generator, num_frames: int, fps: float, mean_on_s: float, mean_off_s: float
) -> np.ndarray:
    """On/off state per frame of a two-state Markov process (exponential durations).

    The initial state is drawn from the stationary distribution, so the sequence
    has no start-up transient. Returns a bool array of shape (num_frames,).
    """
    out = np.zeros(num_frames, dtype=bool)
    on = bool(rng.random() < mean_on_s / (mean_on_s + mean_off_s))
    t, end = 0.0, num_frames / fps
    while t < end:
        dur = rng.exponential(mean_on_s if on else mean_off_s)
        i0, i1 = int(math.ceil(t * fps - 1e-9)), int(math.ceil(min(t + dur, end) * fps - 1e-9))
        out[i0:i1] = on
        t += dur
        on = not on
    return out


@dataclass
class PeopleTrack:
    """Simulated people (numpy), per frame ``f`` and slot ``k``.

    ``active[f, k]`` (in the scene: inside the room or in the corridor),
    ``pose[f, k] = (x, y, heading, gait phase, gait, sit)``, ``visit[f, k]``
    (index into ``appearances``, -1 when inactive), ``door_angle_rad[f]``.
    """

    active: np.ndarray
    pose: np.ndarray
    visit: np.ndarray
    appearances: list[Appearance]
    door_angle_rad: np.ndarray


class AgentTask(enum.StrEnum):
    """What an agent does next; its tasks are ``(AgentTask, argument)`` pairs, in order."""

    WALK = "walk"  # argument: waypoints (x, y) still to reach, popped as reached
    SIT = "sit"  # argument: the seat's index; turn to face its way, then sit down
    DWELL = "dwell"  # argument: seconds left to stay
    STAND = "stand"  # argument: the seat's index, freed once standing
    EXIT = "exit"  # argument: None; leaves the room (frees the slot)


@dataclass
class _Agent:
    appearance: int
    pos: np.ndarray  # (x, y) on the floor (m)
    heading_rad: float
    tasks: list[tuple[AgentTask, Any]] = field(default_factory=list)
    stops_left: int = 0
    phase_rad: float = 0.0
    gait: float = 0.0
    sit: float = 0.0
    seat: int | None = None
    passing: bool = False  # on the way through the doorway (opens the door)


def _turn(h: float, target: float, max_step: float) -> float:
    d = (target - h + math.pi) % (2 * math.pi) - math.pi
    return h + max(-max_step, min(max_step, d))


def simulate_people(
    *,
    rng: np.random.Generator,
    num_frames: int,
    fps: float,
    slots: int,
    people: PeopleConfig,
    nav: NavGrid,
    seats: list[tuple[float, float, float]],
    door: Door | None,
    arrivals_per_s: float = 0.0,
    population: int = 0,
    burn_in_s: float = 0.0,
) -> PeopleTrack:
    """Simulate people frame by frame.

    With a ``door``, people arrive (Poisson, ``arrivals_per_s``) while fewer than
    ``slots`` are present, enter from the corridor through the doorway, make
    ``people.stops`` stops (sitting on a free chair with ``sit_probability``, else
    standing at a random free spot) of ``people.dwell_s`` each, and leave the way
    they came; the door opens when someone is near it or someone props it open.
    Without a door, ``population`` people wander the room for the whole sequence.
    People avoid furniture but not each other (they may overlap briefly).
    With ``people.roster`` set, every visitor is one of the roster's people not
    already present (:func:`~mincam_render.scenes.indoor.people.draw_roster`).

    Raises:
        ValueError: a roster smaller than ``slots`` (someone present would have no look).
    """
    if 0 < people.roster < slots:
        raise ValueError(
            f"people.roster = {people.roster}: need at least max_people = {slots} people "
            "(one look for everyone present at once), or 0 for no roster"
        )
    dt = 1.0 / fps
    burn = int(round(burn_in_s * fps))
    sim = _PeopleSimulation(rng=rng, slots=slots, people=people, nav=nav, seats=seats, door=door)
    if sim.entrance is None:
        sim.populate(population)
    sim.start_door()
    track = PeopleTrack(
        active=np.zeros((num_frames, slots), dtype=bool),
        pose=np.zeros((num_frames, slots, 6)),
        visit=np.full((num_frames, slots), -1, dtype=np.int32),
        appearances=sim.appearances,
        door_angle_rad=np.zeros(num_frames),
    )
    for step in range(burn + num_frames):
        t = step * dt
        if sim.entrance is not None:
            sim.arrive(arrivals_per_s * dt)
        for k in range(slots):
            sim.advance(k, dt)
        if door is not None:
            sim.move_door(t, dt)
        if step >= burn:
            sim.record(track, step - burn)
    return track


class _PeopleSimulation:
    """The state of :func:`simulate_people` between its steps (one random stream, numpy).

    Every random draw is taken here, in the order of the steps: arrivals, each
    slot's next plan, the door's proppings.
    """

    def __init__(
        self,
        *,
        rng: np.random.Generator,
        slots: int,
        people: PeopleConfig,
        nav: NavGrid,
        seats: list[tuple[float, float, float]],
        door: Door | None,
    ) -> None:
        self.rng, self.people, self.nav, self.seats, self.door = rng, people, nav, seats, door
        self.appearances: list[Appearance] = []
        self.roster = draw_roster(people)
        self.agents: list[_Agent | None] = [None] * slots
        self.seat_owner: list[int | None] = [None] * len(seats)
        self.entrance = door.waypoints() if door is not None else None
        self.propped = False
        self.propped_until = 0.0
        self.last_near = -math.inf
        self.angle = 0.0  # door opening (rad)

    def new_agent(self, pos: np.ndarray, stops: int) -> _Agent:
        """A visitor at ``pos`` (x, y) with ``stops`` stops to make, of a newly drawn look."""
        self.appearances.append(self.next_look())
        return _Agent(
            appearance=len(self.appearances) - 1,
            pos=np.asarray(pos, float),
            heading_rad=float(self.rng.uniform(-math.pi, math.pi)),
            stops_left=stops,
        )

    def next_look(self) -> Appearance:
        """A new visitor's look: a fresh draw, or a roster person not present (uniformly)."""
        if not self.roster:
            return Appearance.draw(self.rng, self.people)
        present = {self.appearances[a.appearance].identity for a in self.agents if a is not None}
        absent = [p for p in self.roster if p.identity not in present]
        return absent[int(self.rng.integers(len(absent)))]

    def populate(self, population: int) -> None:
        """Without a door: ``population`` people (at most one a slot) anywhere on the floor."""
        for k in range(min(population, len(self.agents))):
            self.agents[k] = self.new_agent(self.nav.random_point(self.rng), 0)

    def start_door(self) -> None:
        """Draw when the door is first propped open (never when nobody props it)."""
        door_cfg = self.door.config if self.door is not None else None
        if door_cfg is not None and door_cfg.mean_propped_s > 0:
            self.propped_until = self.rng.exponential(door_cfg.mean_unpropped_s)

    def arrive(self, probability: float) -> None:
        """With ``probability``, someone enters from the corridor into the first free slot."""
        if self.entrance is None:  # no door: nobody enters
            return
        if self.rng.random() < probability:
            free_slots = [k for k in range(len(self.agents)) if self.agents[k] is None]
            if free_slots:
                k = free_slots[0]
                corridor, doorway, inside = self.entrance
                stops = self.people.stops
                ag = self.new_agent(corridor, int(self.rng.integers(stops[0], stops[1] + 1)))
                ag.heading_rad = math.atan2(*(doorway - corridor)[::-1])
                ag.tasks = [(AgentTask.WALK, [doorway, inside])]
                ag.passing = True
                self.agents[k] = ag

    def plan_next(self, k: int, ag: _Agent) -> None:
        """Give slot ``k``'s agent its next stop (sit or stand and dwell), or the way out."""
        rng, people, nav, seats = self.rng, self.people, self.nav, self.seats
        if ag.stops_left > 0 or self.entrance is None:
            ag.stops_left -= 1
            ag.passing = False
            free = [i for i, o in enumerate(self.seat_owner) if o is None]
            if free and rng.random() < people.sit_probability:
                si = int(free[rng.integers(len(free))])
                self.seat_owner[si] = k
                ag.seat = si
                goal = np.array(seats[si][:2])
                ag.tasks = [
                    (AgentTask.WALK, nav.plan(ag.pos, goal)[1:]),
                    (AgentTask.SIT, si),
                    (AgentTask.DWELL, float(rng.uniform(*people.dwell_s))),
                    (AgentTask.STAND, si),
                ]
            else:
                goal = nav.random_point(rng)
                ag.tasks = [
                    (AgentTask.WALK, nav.plan(ag.pos, goal)[1:]),
                    (AgentTask.DWELL, float(rng.uniform(*people.dwell_s))),
                ]
        else:
            corridor, doorway, inside = self.entrance
            ag.tasks = [
                (AgentTask.WALK, [*nav.plan(ag.pos, inside)[1:], doorway, corridor]),
                (AgentTask.EXIT, None),
            ]
            ag.passing = True

    def advance(self, k: int, dt: float) -> None:
        """One step (``dt`` s) of slot ``k``'s agent on its current task."""
        ag = self.agents[k]
        if ag is None:
            return
        if not ag.tasks:
            self.plan_next(k, ag)
        kind, arg = ag.tasks[0]
        moving = False
        if kind is AgentTask.WALK:
            self.walk(ag, arg, dt)
            moving = True
            if not arg:
                ag.tasks.pop(0)
        elif kind is AgentTask.SIT:
            target = self.seats[arg][2]
            ag.heading_rad = _turn(ag.heading_rad, target, TURN_RATE_RAD_S * dt)
            if abs((target - ag.heading_rad + math.pi) % (2 * math.pi) - math.pi) < 1e-6:
                ag.sit = min(1.0, ag.sit + SIT_RATE_PER_S * dt)
                if ag.sit >= 1.0:
                    ag.tasks.pop(0)
        elif kind is AgentTask.DWELL:
            ag.tasks[0] = (AgentTask.DWELL, arg - dt)
            if arg - dt <= 0:
                ag.tasks.pop(0)
        elif kind is AgentTask.STAND:
            ag.sit = max(0.0, ag.sit - SIT_RATE_PER_S * dt)
            if ag.sit <= 0.0:
                self.seat_owner[arg] = None
                ag.seat = None
                ag.tasks.pop(0)
        elif kind is AgentTask.EXIT:
            self.agents[k] = None
            return
        ag.gait = (
            min(1.0, ag.gait + GAIT_RATE_PER_S * dt)
            if moving
            else max(0.0, ag.gait - GAIT_RATE_PER_S * dt)
        )

    def walk(self, ag: _Agent, waypoints: list, dt: float) -> None:
        """Move ``ag`` along ``waypoints`` (x, y; popped when reached) for ``dt`` s at its speed."""
        appearance = self.appearances[ag.appearance]
        step_len = appearance.speed_m_s * dt
        while waypoints and step_len > 0:
            d = waypoints[0] - ag.pos
            dist = float(np.linalg.norm(d))
            if dist > 1e-9:
                ag.heading_rad = _turn(ag.heading_rad, math.atan2(d[1], d[0]), TURN_RATE_RAD_S * dt)
            if dist <= step_len:
                ag.pos = np.array(waypoints.pop(0), float)
                step_len -= dist
                ag.phase_rad += 2 * math.pi * dist / (CYCLE_LENGTH_PER_HEIGHT * appearance.height_m)
            else:
                ag.pos = ag.pos + d / dist * step_len
                ag.phase_rad += (
                    2 * math.pi * step_len / (CYCLE_LENGTH_PER_HEIGHT * appearance.height_m)
                )
                step_len = 0.0

    def move_door(self, t: float, dt: float) -> None:
        """One step of the door at time ``t`` (s): open while someone passes or it is propped."""
        if self.door is None:
            return
        door_cfg = self.door.config
        for ag in self.agents:
            if (
                ag is not None
                and ag.passing
                and np.linalg.norm(ag.pos - self.door.center[:2]) < door_cfg.trigger_distance_m
            ):
                self.last_near = t
        if door_cfg.mean_propped_s > 0 and t >= self.propped_until:
            self.propped = not self.propped
            self.propped_until = t + self.rng.exponential(
                door_cfg.mean_propped_s if self.propped else door_cfg.mean_unpropped_s
            )
        target = (
            math.radians(door_cfg.max_angle_deg)
            if (self.propped or t - self.last_near <= door_cfg.hold_open_s)
            else 0.0
        )
        step_a = math.radians(door_cfg.speed_deg_s) * dt
        self.angle += max(-step_a, min(step_a, target - self.angle))

    def record(self, track: PeopleTrack, f: int) -> None:
        """Write the door and every occupied slot into frame ``f`` of ``track``."""
        track.door_angle_rad[f] = self.angle
        for k, ag in enumerate(self.agents):
            if ag is None:
                continue
            track.active[f, k] = True
            track.visit[f, k] = ag.appearance
            track.pose[f, k] = (ag.pos[0], ag.pos[1], ag.heading_rad, ag.phase_rad, ag.gait, ag.sit)


def track_state(track: PeopleTrack, index: int) -> tuple[tuple[Appearance, Pose], ...]:
    """The people of frame ``index`` of a simulation, in slot order."""
    out = []
    for k in np.flatnonzero(track.active[index]):
        x, y, hd, ph, g, s = track.pose[index, k]
        out.append(
            (
                track.appearances[track.visit[index, k]],
                Pose(float(x), float(y), float(hd), float(ph), float(g), float(s)),
            )
        )
    return tuple(out)
