r"""Closed-form radiometry of the freeform pixel geometry (float64 numpy).

For two parallel rectangles facing each other at distance ``z`` (a detector and
a region of its mask plane), the coupling integral

.. math::

    \mathcal{G} = \int_{A_1}\int_{A_2} \frac{\cos\theta_1\cos\theta_2}{r^2}
        \,dA_2\,dA_1 = \pi A_1 F_{12}

has a closed form (the view factor between parallel rectangles, obtained by
contour integration; e.g. Howell's catalogue of configuration factors):

.. math::

    \mathcal{G} = \tfrac12 \sum_{i,j,k,l \in \{1,2\}} (-1)^{i+j+k+l}\,
        g(x_i - \xi_k,\; y_j - \eta_l), \quad
    g(u, v) = v\sqrt{u^2+z^2}\,\operatorname{atan}\tfrac{v}{\sqrt{u^2+z^2}}
            + u\sqrt{v^2+z^2}\,\operatorname{atan}\tfrac{u}{\sqrt{v^2+z^2}}
            - \tfrac{z^2}{2}\ln(u^2+v^2+z^2).

A uniform radiance ``L`` seen through a fully open aperture ``A_2`` delivers
``P = L * G`` watts onto ``A_1``.
"""

from __future__ import annotations

import numpy as np


def _g(u: float, v: float, z: float) -> float:
    su = np.sqrt(u * u + z * z)
    sv = np.sqrt(v * v + z * z)
    return (
        v * su * np.arctan(v / su)
        + u * sv * np.arctan(u / sv)
        - 0.5 * z * z * np.log(u * u + v * v + z * z)
    )


def parallel_rectangles_coupling(
    rect1_m: tuple[float, float, float, float],
    rect2_m: tuple[float, float, float, float],
    distance_m: float,
) -> float:
    """Coupling integral of two parallel, axis-aligned rectangles (m^2).

    Args:
        rect1_m: ``(x_min, x_max, y_min, y_max)`` of the first rectangle (m).
        rect2_m: the same for the second rectangle, in the same (x, y) frame (m).
        distance_m: separation of the two planes (m), > 0.

    Returns:
        ``int int cos1 cos2 / r^2 dA dA`` in m^2 (multiply by radiance for watts).

    Raises:
        ValueError: non-positive distance or empty rectangles.

    """
    x1, x2, y1, y2 = map(float, rect1_m)
    k1, k2, l1, l2 = map(float, rect2_m)
    if not distance_m > 0:
        raise ValueError(f"distance_m = {distance_m!r} must be > 0")
    if not (x2 > x1 and y2 > y1 and k2 > k1 and l2 > l1):
        raise ValueError(f"rectangles {rect1_m}, {rect2_m} need min < max on both axes")
    total = 0.0
    for i, x in enumerate((x1, x2)):
        for j, y in enumerate((y1, y2)):
            for k, xi in enumerate((k1, k2)):
                for m, eta in enumerate((l1, l2)):
                    sign = -1.0 if (i + j + k + m) % 2 else 1.0
                    total += sign * float(_g(np.float64(x - xi), np.float64(y - eta), distance_m))
    return 0.5 * float(total)
