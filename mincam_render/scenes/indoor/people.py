"""People: how each visitor looks, how they stand, walk or sit, and their meshes."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import trimesh

from mincam_render.scenes.indoor.config import PeopleConfig
from mincam_render.scenes.indoor.geometry import merge_meshes

#: Where people who are not in the scene are parked (m): far below the floor, unseen.
PARK_POSITION_M = (0.0, 0.0, -50.0)


@dataclass(frozen=True)
class Appearance:
    """One visitor's body: stature (m), build (width scale), albedos, walking speed (m/s).

    ``identity``: the roster's person (0 .. N-1), or -1 for a one-off visitor.
    """

    height_m: float
    build: float
    upper_albedo: float
    lower_albedo: float
    skin_albedo: float
    speed_m_s: float
    identity: int = -1

    @property
    def radius_m(self) -> float:
        """Footprint radius (m): half the shoulder width."""
        return 0.22 * self.build * self.height_m / 1.75

    @staticmethod
    def draw(rng: np.random.Generator, people: PeopleConfig) -> Appearance:
        return Appearance(
            height_m=float(rng.uniform(*people.height_m)),
            build=float(rng.uniform(*people.build)),
            upper_albedo=float(rng.uniform(*people.clothing_albedo)),
            lower_albedo=float(rng.uniform(*people.clothing_albedo)),
            skin_albedo=float(rng.uniform(*people.skin_albedo)),
            speed_m_s=float(rng.uniform(*people.walk_speed_m_s)),
        )


def draw_roster(people: PeopleConfig) -> tuple[Appearance, ...]:
    """The ``people.roster`` fixed people, drawn from ``people.roster_seed`` (numpy).

    The draw depends on the description only, never on an episode's seed, so
    every episode shows the same people (identity ``i`` is the ``i``-th draw).
    """
    rng = np.random.default_rng(people.roster_seed)
    return tuple(replace(Appearance.draw(rng, people), identity=i) for i in range(people.roster))


#: A person standing still, used for slots nobody occupies.
DEFAULT_APPEARANCE = Appearance(1.75, 1.0, 0.3, 0.2, 0.35, 1.2)


@dataclass(frozen=True)
class Pose:
    """Where a person is and how their limbs are posed.

    Args:
        x, y: pelvis position on the floor (m).
        heading_rad: facing direction, from +x toward +y.
        gait_phase_rad: walking cycle phase.
        gait: walking amplitude, 0 (still) to 1 (walking).
        sit: 0 standing to 1 seated.
    """

    x: float
    y: float
    heading_rad: float = 0.0
    gait_phase_rad: float = 0.0
    gait: float = 0.0
    sit: float = 0.0


def _rot_fwd(theta: float) -> np.ndarray:
    """Rotation about local y that swings a limb hanging along -z forward (+x) by theta."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, 0, -s], [0, 1, 0], [s, 0, c]])


class BodyModel:
    """Articulated low-poly person: three meshes (clothes upper, clothes lower, skin).

    Proportions are fractions of stature (thigh and shin 0.245, pelvis at 0.53
    standing); widths scale with build. Face counts do not depend on the person.
    """

    PARTS = ("upper", "lower", "skin")

    def __init__(self) -> None:
        cyl = trimesh.creation.cylinder(radius=1.0, height=1.0, sections=8)
        self._limb = (np.asarray(cyl.vertices) - [0, 0, 0.5], np.asarray(cyl.faces))  # z in [-1, 0]
        torso = trimesh.creation.cylinder(radius=1.0, height=1.0, sections=12)
        self._torso = (
            np.asarray(torso.vertices) + [0, 0, 0.5],
            np.asarray(torso.faces),
        )  # z in [0, 1]
        head = trimesh.creation.icosphere(subdivisions=1)
        self._head = (np.asarray(head.vertices), np.asarray(head.faces))
        box = trimesh.creation.box(extents=(1, 1, 1))
        self._foot = (np.asarray(box.vertices), np.asarray(box.faces))
        # fixed layout of the parts in each mesh (for faces)
        self.faces = {
            "upper": merge_meshes([self._torso] + [self._limb] * 4)[1],
            "lower": merge_meshes([self._limb] * 4 + [self._foot] * 2)[1],
            "skin": merge_meshes([self._head, self._limb])[1],
        }

    def vertices(self, a: Appearance, p: Pose) -> dict[str, np.ndarray]:
        """World vertices of each mesh for appearance ``a`` in pose ``p``."""
        h, b = a.height_m, a.build
        s = h / 1.75
        leg = 0.245 * h
        ankle = 0.04 * h
        sit_thigh = p.sit * math.pi / 2
        hz = leg * (math.cos(sit_thigh) + 1.0) + ankle
        amp = 0.45 * p.gait
        limbs_lo = []
        feet = []
        for side, ph in ((1.0, p.gait_phase_rad), (-1.0, p.gait_phase_rad + math.pi)):
            walk_thigh = amp * math.sin(ph)
            walk_shin = walk_thigh - amp * 0.9 * (0.5 - 0.5 * math.cos(ph + 0.6))
            thigh = (1 - p.sit) * walk_thigh + sit_thigh
            shin = (1 - p.sit) * walk_shin
            hip = np.array([0.0, side * 0.09 * b * s, hz])
            r_t, r_s = _rot_fwd(thigh), _rot_fwd(shin)
            knee = hip + r_t @ np.array([0, 0, -leg])
            limbs_lo.append(self._place(self._limb, hip, r_t, (0.065 * b * s, 0.065 * b * s, leg)))
            limbs_lo.append(self._place(self._limb, knee, r_s, (0.05 * b * s, 0.05 * b * s, leg)))
            ank = knee + r_s @ np.array([0, 0, -leg])
            feet.append(
                self._place(
                    self._foot,
                    ank + r_s @ np.array([0.05 * s, 0, -ankle / 2]),
                    r_s,
                    (0.24 * s, 0.09 * s, ankle),
                )
            )
        torso_h = 0.31 * h
        upper = [
            self._place(
                self._torso,
                np.array([0, 0, hz - 0.02 * h]),
                np.eye(3),
                (0.11 * b * s, 0.18 * b * s, torso_h),
            )
        ]
        for side, ph in ((1.0, p.gait_phase_rad), (-1.0, p.gait_phase_rad + math.pi)):
            walk_arm = -0.7 * amp * math.sin(ph)
            arm = (1 - p.sit) * walk_arm + p.sit * 0.35
            fore = (1 - p.sit) * (walk_arm + 0.2 * p.gait) + p.sit * 1.4
            sh = np.array([0.0, side * (0.18 * b + 0.04) * s, hz + 0.28 * h])
            r_a, r_f = _rot_fwd(arm), _rot_fwd(fore)
            elbow = sh + r_a @ np.array([0, 0, -0.17 * h])
            upper.append(self._place(self._limb, sh, r_a, (0.04 * b * s, 0.04 * b * s, 0.17 * h)))
            upper.append(
                self._place(self._limb, elbow, r_f, (0.035 * b * s, 0.035 * b * s, 0.17 * h))
            )
        skin = [
            self._place(
                self._head,
                np.array([0, 0, hz + 0.405 * h]),
                np.eye(3),
                (0.055 * h, 0.05 * h, 0.065 * h),
            ),
            self._place(
                self._limb,
                np.array([0, 0, hz + 0.36 * h]),
                np.eye(3),
                (0.03 * s, 0.03 * s, 0.08 * h),
            ),
        ]
        c, sn = math.cos(p.heading_rad), math.sin(p.heading_rad)
        world = np.array([[c, -sn, 0], [sn, c, 0], [0, 0, 1]])
        pos = np.array([p.x, p.y, 0.0])
        out = {}
        for name, parts in (("upper", upper), ("lower", limbs_lo + feet), ("skin", skin)):
            out[name] = np.concatenate(parts) @ world.T + pos
        return out

    def parked(self) -> dict[str, np.ndarray]:
        """Vertices of an unused slot: a standing person far below the floor."""
        x, y, z = PARK_POSITION_M
        v = self.vertices(DEFAULT_APPEARANCE, Pose(x, y))
        return {k: vv + np.array([0, 0, z]) for k, vv in v.items()}

    @staticmethod
    def _place(
        mesh: tuple[np.ndarray, np.ndarray],
        origin: np.ndarray,
        rot: np.ndarray,
        scale: tuple[float, float, float],
    ) -> np.ndarray:
        return (mesh[0] * np.asarray(scale)) @ rot.T + origin
