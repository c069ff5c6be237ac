r"""Point, spot and directional lights seen by the detectors straight through their masks.

A ray traced out from the detector (:mod:`mincam_render.render.transport`) never
hits a delta light (a point, a spot, a directional light, the sun): it has no
area and no extent in angle. The scene's integrator still brings their light
in once it has bounced off something, but the light such an emitter sends
straight through the mask onto the diode has to be connected explicitly. This
is the sun path's patch strategy (:mod:`mincam_render.render.sun_patch`) turned
around: there a point sampled on the window follows the sun's beam to the
sunlit patch behind it; here a point ``x`` sampled on a mask texel follows the
light's ray back through the mask to the detector plane, where it lands at
``q``.

For a delta light, the paper's integral over the mask collapses:
``\int L(q \to x) \cos\theta_x / |x - q|^2 dx = E(q)``, the light's irradiance
normal to the ray at ``q`` (``I / r^2`` for a point of intensity ``I`` at
distance ``r``, times the cone falloff for a spot; the irradiance ``E`` of a
directional light). So the texel ``(v, u)`` crossed by the ray from ``q`` to
the light passes

.. math::

    T(v, u) = \int_{A_d} E(q) \cos\theta_q\, f(\theta_q)\, V\,
        [x(q) \in (v, u)]\, dq
            = \int_{(v, u) \cap F} E(x) \cos\theta\, f(\theta)\, V(x)\, dx,

where ``V`` is the visibility of the light from the mask and ``F`` is the
detector's footprint on the mask plane: the points whose ray to the light
comes from the detector. The change of variables is exact: a light at height
``h > d`` above the detector plane maps the detector square onto ``F``, the
square scaled by ``\mu = 1 - d / h`` about the light's foot, with
``dx = \mu^2 dq`` and ``|x - p| = \mu |q - p|``, so ``E(q) dq = E(x) dx``;
the ray's direction (the spot's falloff, ``\theta``) is the same at ``q`` and
``x``. A directional light shifts the square by ``d \tan\theta`` (``\mu = 1``).

Each ray of the transport pass draws ``x`` uniformly on its texel's share of
the footprint, ``(v, u) \cap F`` (an axis-aligned rectangle), and weighs the
light there by that share's area: every sample inside the footprint counts,
texels outside it cost one test and no ray, and the texel's mean over its
samples is unbiased, so the sums stay ordered (no scatter, no atomics) and a
seed gives the same image. The visibility ray leaves from ``x``; the board
itself is not part of the scene.

Emitters with a delta position (``point``, ``spot``, ``projector``) and
infinite directional emitters (``directional``) are connected;
``directionalarea`` (a surface emitting along its normal only) is not.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, NamedTuple

import drjit as dr
import mitsuba as mi

from mincam_render.render.board import Board

if TYPE_CHECKING:  # mi.Float exists once a variant is set
    #: Directional response beyond Lambert, per ray: ``f(cos theta)`` (1.0 for none).
    Response = Callable[[mi.Float], mi.Float | float]


class TexelRect(NamedTuple):
    """A mask texel in board-frame coordinates from the detector centre (Dr.Jit, m).

    Attributes:
        s_lo, s_hi: its extent along ``right``.
        t_lo, t_hi: its extent along ``up``.
    """

    s_lo: mi.Float
    s_hi: mi.Float
    t_lo: mi.Float
    t_hi: mi.Float


def _positional(emitter: mi.Emitter) -> bool:
    return mi.has_flag(emitter.flags(), mi.EmitterFlags.DeltaPosition)


def _directional(emitter: mi.Emitter) -> bool:
    flags = emitter.flags()
    return mi.has_flag(flags, mi.EmitterFlags.DeltaDirection) and mi.has_flag(
        flags, mi.EmitterFlags.Infinite
    )


def delta_emitters(scene: mi.Scene) -> list[mi.Emitter]:
    """The emitters of ``scene`` the transport connects to explicitly (see the module docstring).

    Returns:
        Its point, spot and projector lights (a delta position) and directional
        lights (a delta direction at infinity), in the scene's order.
    """
    return [e for e in scene.emitters() if _positional(e) or _directional(e)]


def _footprint(emitter: mi.Emitter, board: Board) -> tuple[mi.Float, mi.Float, mi.Float, mi.Bool]:
    """The detector's footprint ``F`` on the mask plane seen from ``emitter``.

    Args:
        emitter: a point-like or directional emitter (see :func:`delta_emitters`).
        board: the ray's board.

    Returns:
        ``(c_s, c_t, half, lit)``: the footprint's centre in board-frame
        coordinates from the detector centre (m), its half side (m), and whether
        the light lies beyond the mask plane (in front of the board).
    """
    it = dr.zeros(mi.Interaction3f)
    it.p = board.center
    ds, _ = emitter.sample_direction(it, mi.Point2f(0.5, 0.5), True)
    if _positional(emitter):
        rel = ds.p - board.center
        height = dr.dot(rel, board.fwd)
        lit = height > board.dist
        scale = board.dist / dr.select(lit, height, 1.0)
        half = 0.5 * board.a_det * (1.0 - scale)
    else:  # toward the light, from anywhere
        rel = ds.d
        height = dr.dot(rel, board.fwd)
        lit = height > 0.0
        scale = board.dist / dr.select(lit, height, 1.0)
        half = 0.5 * board.a_det
    return dr.dot(rel, board.right) * scale, dr.dot(rel, board.up) * scale, half, lit


def _through_texel(
    scene: mi.Scene,
    emitter: mi.Emitter,
    sampler: mi.Sampler,
    board: Board,
    texel: TexelRect,
    response: Response,
) -> mi.Float:
    """One sample of ``T(v, u)`` from one emitter (W per unit transmittance), per ray.

    Args:
        scene: the scene (for the visibility ray).
        emitter: a point-like or directional emitter.
        sampler: draws one 2D sample (the point ``x`` on the texel's share of the footprint).
        board: the ray's board.
        texel: the ray's mask texel.
        response: the diode's directional response beyond Lambert.
    """
    c_s, c_t, half, lit = _footprint(emitter, board)
    s_lo, s_hi = dr.maximum(texel.s_lo, c_s - half), dr.minimum(texel.s_hi, c_s + half)
    t_lo, t_hi = dr.maximum(texel.t_lo, c_t - half), dr.minimum(texel.t_hi, c_t + half)
    lit &= (s_hi > s_lo) & (t_hi > t_lo)
    xi = sampler.next_2d()
    it = dr.zeros(mi.Interaction3f)
    it.p = (
        board.center
        + board.fwd * board.dist
        + board.right * dr.lerp(s_lo, s_hi, xi.x)
        + board.up * dr.lerp(t_lo, t_hi, xi.y)
    )
    ds, irradiance = emitter.sample_direction(it, mi.Point2f(0.5, 0.5), lit)
    shadow = it.spawn_ray_to(ds.p) if _positional(emitter) else it.spawn_ray(ds.d)
    lit &= ~scene.ray_test(shadow, lit)
    cos_theta = dr.dot(ds.d, board.fwd)
    area = (s_hi - s_lo) * (t_hi - t_lo)
    value = mi.Float(irradiance[0]) * cos_theta * response(cos_theta) * area
    return dr.select(lit, value, 0.0)


def delta_light_transport(
    scene: mi.Scene,
    emitters: Sequence[mi.Emitter],
    sampler: mi.Sampler,
    board: Board,
    texel: TexelRect,
    response: Response,
) -> mi.Float:
    """One sample per ray of the delta lights' share of ``T(v, u)`` (W per unit transmittance).

    The mean over a texel's rays is an unbiased estimate of the power the
    ``emitters`` send straight through that texel onto the detector (the
    module docstring's integral); 0 for texels no light reaches.

    Args:
        scene: the scene (for the visibility rays).
        emitters: its point-like and directional emitters (:func:`delta_emitters`).
        sampler: draws one 2D sample per emitter.
        board: each ray's board.
        texel: each ray's mask texel.
        response: the diode's directional response beyond Lambert, ``f(cos theta)``.

    Returns:
        Per ray, the sum over ``emitters`` (W).
    """
    total = mi.Float(0.0)
    for emitter in emitters:
        total += _through_texel(scene, emitter, sampler, board, texel, response)
    return total
