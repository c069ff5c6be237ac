r"""Transport of the patches scene as a linear operator on the plane's radiance image.

The patches scene (:mod:`.patches`) is one flat emitter, a rectangle whose
radiance is the image ``L[row, col]`` (W m^-2 sr^-1, nearest filtered), with no
other geometry: every transport ray either hits the plane and returns the
radiance of one texel, or misses and returns 0. Transport is therefore linear
in ``L``:

.. math::

    T[k, v, u] = \sum_j W[(k, v, u), j]\, L_j

with ``j = row * n + col`` over the ``n x n`` plane texels. :func:`build_plane_transport`
estimates ``W`` once per camera by Monte Carlo with the same estimator as
:func:`mincam_render.render.transport.render_transport` (samples stratified per texel,
``x`` uniform in the mask texel,
``q`` on the detector from the same one-sample mixture of area and
cosine-weighted sampling, weight ``A_t d^2 / |x-q|^4 f(theta) / p(q)``), tracing
the rays to the plane in numpy instead of Mitsuba. Then a frame costs one
sparse product instead of a render (about 0.3 ms instead of 30 ms), and
``E[W L] = E[render_transport]``; only the Monte Carlo noise differs (W's noise
is that of a ``spp``-sample render, fixed across frames).

Plane texel ``(row, col)``: row 0 is the rectangle's ``up`` edge, column 0 its
left edge as seen from the camera it faces (as
:func:`mincam_render.render.mitsuba_scene.textured_emitter_rectangle`).
All arrays here are numpy except :attr:`PlaneTransport.matrix` (torch sparse CSR).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np
import torch

from mincam_render.core.checks import check_int, check_number
from mincam_render.optics.camera import FreeformCamera
from mincam_render.render.transport import cosine_sampling_fraction
from mincam_render.scenes.patches import PatchesFamily

#: Samples per texel of the operator used by the benchmark: its noise is that of a
#: 4096-spp render (32x below the 4-spp training renders).
DEFAULT_OPERATOR_SPP = 4096
#: Monte Carlo samples held in memory at once while building an operator.
_SAMPLES_PER_CHUNK = 1 << 21
#: Samples of the directional-response table, as in :mod:`mincam_render.render.transport`.
_RESPONSE_TABLE_SIZE = 181


@dataclass(frozen=True, kw_only=True)
class PlaneGeometry:
    """A square emitting plane in world space (metres), with its image orientation.

    Args:
        center_m: world position of the plane's centre, shape (3,) (m).
        facing_m: a world point in front of the plane (the camera), shape (3,) (m).
        up: world direction of image row 0 (made orthogonal to the normal), shape (3,).
        side_m: side of the square (m), > 0.
        resolution: texels per side of the radiance image, >= 1.

    """

    center_m: tuple[float, float, float]
    facing_m: tuple[float, float, float]
    up: tuple[float, float, float]
    side_m: float
    resolution: int

    def __post_init__(self) -> None:
        for name in ("center_m", "facing_m", "up"):
            v = np.asarray(getattr(self, name), dtype=np.float64)
            if v.shape != (3,) or not np.all(np.isfinite(v)):
                raise ValueError(
                    f"PlaneGeometry.{name} = {getattr(self, name)!r}: allowed 3 finite numbers"
                )
            object.__setattr__(self, name, tuple(float(x) for x in v))
        check_number(
            "PlaneGeometry.side_m", self.side_m, 0, 1e6, unit="m", lo_open=True, hi_open=True
        )
        check_int("PlaneGeometry.resolution", self.resolution, 1, 8192, numpy=True)
        z = np.subtract(self.facing_m, self.center_m)
        if np.linalg.norm(z) < 1e-12:
            raise ValueError(f"PlaneGeometry.facing_m = {self.facing_m}: must differ from center_m")
        if np.linalg.norm(np.cross(z, self.up)) < 1e-9 * np.linalg.norm(z) * np.linalg.norm(
            self.up
        ):
            raise ValueError(f"PlaneGeometry.up = {self.up}: must not be parallel to the normal")

    @classmethod
    def of(cls, family: PatchesFamily) -> PlaneGeometry:
        """The plane of a patches family (as :meth:`PatchesFamily.build_scene` places it)."""
        centre, up, cam_pos, side = family._plane_geometry()
        return cls(
            center_m=tuple(centre),
            facing_m=tuple(cam_pos),
            up=tuple(up),
            side_m=float(side),
            resolution=int(family.config.image_resolution),
        )

    @property
    def axes(self) -> np.ndarray:
        """World axes ``[x, y, z]`` of the plane, shape (3, 3).

        ``z`` is the front normal (toward ``facing_m``); ``x = up x z`` points to
        the right of a viewer the plane faces and ``y = z x x`` up, as in Mitsuba's
        ``look_at`` transform of the rectangle.
        """
        z = np.subtract(self.facing_m, self.center_m)
        z = z / np.linalg.norm(z)
        x = np.cross(self.up, z)
        x /= np.linalg.norm(x)
        return np.stack([x, np.cross(z, x), z])

    def texel_centers_m(self) -> np.ndarray:
        """World positions of the image texel centres, shape (n, n, 3), ``[row, col]`` (m)."""
        n = self.resolution
        ax, ay, _ = self.axes
        s = ((np.arange(n) + 0.5) / n - 0.5) * self.side_m  # along x, by column
        t = (0.5 - (np.arange(n) + 0.5) / n) * self.side_m  # along y, by row (row 0 = up)
        return np.asarray(self.center_m) + s[None, :, None] * ax + t[:, None, None] * ay

    def hit_texel(self, origin_m: np.ndarray, direction: np.ndarray) -> np.ndarray:
        """Flat image texel ``row * n + col`` hit by rays, or -1 (miss or back face).

        Args:
            origin_m: ray origins, shape (N, 3) (m).
            direction: ray directions (any length), shape (N, 3).

        Returns:
            int64 array (N,).
        """
        ax, ay, az = self.axes
        denom = direction @ az
        rel = np.asarray(self.center_m) - origin_m
        with np.errstate(divide="ignore", invalid="ignore"):
            dist = (rel @ az) / denom
        front = (denom < 0) & (dist > 0)  # one-sided emitter: rays travelling against z
        hit = origin_m + dist[:, None] * direction - np.asarray(self.center_m)
        # Mitsuba's rectangle: uv = (local + 1) / 2; bitmap row 0 is local -y, and
        # emitter_image_data flips rows, so image row = n - 1 - floor(v n).
        n = self.resolution
        with np.errstate(invalid="ignore"):
            u = (hit @ ax) / self.side_m + 0.5
            v = (hit @ ay) / self.side_m + 0.5
        inside = front & (u >= 0) & (u < 1) & (v >= 0) & (v < 1)
        col = np.floor(np.where(inside, u, 0.0) * n).astype(np.int64)
        row = n - 1 - np.floor(np.where(inside, v, 0.0) * n).astype(np.int64)
        col = np.clip(col, 0, n - 1)
        row = np.clip(row, 0, n - 1)
        return np.where(inside, row * n + col, -1)


@dataclass(frozen=True, kw_only=True)
class PlaneTransport:
    """Linear transport of a camera looking at an emitting plane: ``T = W L``.

    Args:
        matrix: ``W[(k, v, u), row * n + col]``, torch sparse CSR float32 of shape
            ``(K * R * C, n * n)``: watts per unit transmittance per W m^-2 sr^-1
            of plane texel radiance (m^2 sr).
        camera: the camera ``W`` was built for.
        plane: the emitting plane.
        spp: Monte Carlo samples per mask texel used to build ``W``.
        seed: seed of those samples.

    """

    matrix: torch.Tensor
    camera: FreeformCamera
    plane: PlaneGeometry
    spp: int
    seed: int

    def __post_init__(self) -> None:
        rows, cols = self.camera.mask_resolution
        n = self.plane.resolution
        shape = (self.camera.num_detectors * rows * cols, n * n)
        if not isinstance(self.matrix, torch.Tensor) or self.matrix.layout != torch.sparse_csr:
            raise ValueError("PlaneTransport.matrix: allowed a torch sparse CSR tensor")
        if tuple(self.matrix.shape) != shape:
            raise ValueError(
                f"PlaneTransport.matrix has shape {tuple(self.matrix.shape)}: expected {shape} "
                "(detectors x mask texels, plane texels)"
            )

    @property
    def transport_shape(self) -> tuple[int, int, int]:
        """``(K, R, C)`` of one frame's transport images."""
        rows, cols = self.camera.mask_resolution
        return (self.camera.num_detectors, rows, cols)

    def apply(self, radiance_w_m2_sr: np.ndarray) -> np.ndarray:
        """Transport images of plane radiance images.

        Args:
            radiance_w_m2_sr: ``L[frame, row, col]`` (or one ``L[row, col]``),
                W m^-2 sr^-1, ``n x n`` as the plane.

        Returns:
            ``T[frame, detector, row, col]`` float32 (W per unit transmittance); a
            single image gives ``T[detector, row, col]``.
        """
        img = np.asarray(radiance_w_m2_sr, dtype=np.float32)
        n = self.plane.resolution
        single = img.ndim == 2
        if single:
            img = img[None]
        if img.ndim != 3 or img.shape[1:] != (n, n):
            raise ValueError(
                f"radiance image of shape {np.shape(radiance_w_m2_sr)}: expected (frames, {n}, {n})"
            )
        flat = torch.from_numpy(np.ascontiguousarray(img.reshape(len(img), n * n).T))
        out = torch.sparse.mm(self.matrix, flat).T.numpy()
        out = np.ascontiguousarray(out).reshape(len(img), *self.transport_shape)
        return out[0] if single else out


def _response_table(camera: FreeformCamera) -> np.ndarray:
    if camera.directional_response is None:
        return np.ones(_RESPONSE_TABLE_SIZE)
    return camera.directional_response.uniform_table(_RESPONSE_TABLE_SIZE).astype(np.float64)


def _stratified_samples(rng: np.random.Generator, n_texels: int, spp: int) -> np.ndarray:
    """``[n_texels * spp, 5]`` uniforms, each texel's ``spp`` stratified like the renders'.

    Columns (0, 1) and (2, 3) are jittered points of an ``a x b`` grid
    (``a = floor(sqrt(spp))``, ``b = ceil(spp / a)``; ``spp`` of its cells drawn
    without replacement, in a random order per texel and pair) and column 4 is
    jittered over ``spp`` strata: every sample stays uniform on its own, so the
    operator stays unbiased, and its noise follows the stratified samples of
    :func:`mincam_render.render.transport.render_transport`.
    """
    a = math.isqrt(spp)
    b = -(-spp // a)

    def cells(count: int) -> np.ndarray:
        return np.argsort(rng.random((n_texels, count)), axis=1)[:, :spp].ravel()

    out = np.empty((n_texels * spp, 5))
    for col in (0, 2):
        cell = cells(a * b)
        out[:, col] = (cell % a + rng.random(cell.size)) / a
        out[:, col + 1] = (cell // a + rng.random(cell.size)) / b
    out[:, 4] = (cells(spp) + rng.random(n_texels * spp)) / spp
    return out


@dataclass(frozen=True)
class _OperatorGeometry:
    """What the operator's samples need of a camera (numpy float64, metres, board frame).

    Attributes:
        rows, cols: mask texels per detector.
        right, up, fwd: ``(3,)`` world unit vectors of the board frame.
        centers: ``[detector, xyz]`` world detector centres (m).
        a_det: detector side (m).
        w_mask: mask side (m).
        dist: mask-to-detector distance (m).
        c_cos: probability of the cosine-weighted technique for ``q`` (0-1).
        table: directional response over ``theta`` in [0, pi/2] (dimensionless).
    """

    rows: int
    cols: int
    right: np.ndarray
    up: np.ndarray
    fwd: np.ndarray
    centers: np.ndarray
    a_det: float
    w_mask: float
    dist: float
    c_cos: float
    table: np.ndarray

    @classmethod
    def of(cls, camera: FreeformCamera) -> _OperatorGeometry:
        """The geometry of ``camera`` (the parallax of each detector included)."""
        rows, cols = camera.mask_resolution
        right, up, fwd = camera.frame
        return cls(
            rows=rows,
            cols=cols,
            right=right,
            up=up,
            fwd=fwd,
            centers=camera.detector_centers_m,
            a_det=camera.detector_size_m,
            w_mask=camera.mask_size_m,
            dist=camera.mask_distance_m,
            c_cos=cosine_sampling_fraction(camera),
            table=_response_table(camera),
        )


def _check_operator_args(spp: int, seed: int) -> None:
    """Raise ``ValueError`` naming ``spp`` or ``seed`` of :func:`build_plane_transport`."""
    check_int("build_plane_transport: spp", spp, 1, 1 << 20)
    check_int("build_plane_transport: seed", seed, 0)


def _sample_points(
    geo: _OperatorGeometry, xi: np.ndarray, u: np.ndarray, v: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Mask point ``x`` and detector point ``q`` per sample, as the renders draw them.

    Args:
        geo: the camera.
        xi: ``[sample, 5]`` uniforms (:func:`_stratified_samples`).
        u: ``(n,)`` mask texel column per sample.
        v: ``(n,)`` mask texel row per sample.

    Returns:
        ``(x_s, x_t, q_s, q_t)``, each ``(n,)``: board-frame coordinates (right, up)
        of ``x`` and ``q`` relative to the detector centre (m).
    """
    w_mask, dist, a_det = geo.w_mask, geo.dist, geo.a_det
    x_s = (u + xi[:, 0]) * (w_mask / geo.cols) - 0.5 * w_mask
    x_t = 0.5 * w_mask - (v + xi[:, 1]) * (w_mask / geo.rows)
    pick_cos = xi[:, 4] < geo.c_cos
    # cosine-weighted direction (pdf cos/pi per solid angle), any warp of that density
    rad, phi = np.sqrt(xi[:, 2]), 2.0 * math.pi * xi[:, 3]
    wx, wy = rad * np.cos(phi), rad * np.sin(phi)
    wz = np.sqrt(np.maximum(1.0 - rad * rad, 1e-300))
    q_s = np.where(pick_cos, x_s - wx / wz * dist, (xi[:, 2] - 0.5) * a_det)
    q_t = np.where(pick_cos, x_t - wy / wz * dist, (xi[:, 3] - 0.5) * a_det)
    return x_s, x_t, q_s, q_t


def _sample_weights(
    geo: _OperatorGeometry,
    q_s: np.ndarray,
    q_t: np.ndarray,
    ds: np.ndarray,
    dt: np.ndarray,
    spp: int,
) -> np.ndarray:
    """``A_t d^2 / |x-q|^4 f(theta) / p(q) / spp`` per sample (m^2 sr), 0 off the detector.

    Args:
        geo: the camera.
        q_s: ``(n,)`` detector point along ``right`` (m, from the detector centre).
        q_t: ``(n,)`` detector point along ``up`` (m).
        ds: ``(n,)`` ``x - q`` along ``right`` (m).
        dt: ``(n,)`` ``x - q`` along ``up`` (m).
        spp: samples per mask texel.
    """
    a_det, dist, c_cos, table = geo.a_det, geo.dist, geo.c_cos, geo.table
    texel_area = geo.w_mask * geo.w_mask / (geo.rows * geo.cols)
    on_det = (np.abs(q_s) <= 0.5 * a_det) & (np.abs(q_t) <= 0.5 * a_det)
    r2 = ds * ds + dt * dt + dist * dist
    g = dist * dist / (r2 * r2)  # cos_q cos_x / r^2
    theta = np.arccos(np.clip(dist / np.sqrt(r2), 0.0, 1.0))
    f_dir = np.interp(theta, np.linspace(0.0, 0.5 * math.pi, len(table)), table)
    pdf_q = (1.0 - c_cos) / (a_det * a_det) + c_cos * g / math.pi
    return np.where(on_det, g * f_dir * texel_area / pdf_q, 0.0) / spp


def _chunk_entries(
    plane: PlaneGeometry,
    geo: _OperatorGeometry,
    rng: np.random.Generator,
    texel: np.ndarray,
    spp: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Trace the samples of one chunk to the plane.

    Args:
        plane: the emitting plane.
        geo: the camera.
        rng: the operator's generator (advanced by this chunk's draws).
        texel: ``(n,)`` flat mask texel ``(k * rows + v) * cols + u`` per sample,
            ``spp`` consecutive samples per texel.
        spp: samples per mask texel.

    Returns:
        ``(key, weight)``: flat ``W`` index ``texel * n_plane_texels + j`` (int64)
        and weight (m^2 sr) of every sample that hits plane texel ``j``.
    """
    u = texel % geo.cols
    v = (texel // geo.cols) % geo.rows
    k = texel // (geo.cols * geo.rows)
    xi = _stratified_samples(rng, len(texel) // spp, spp)
    x_s, x_t, q_s, q_t = _sample_points(geo, xi, u, v)
    ds, dt = x_s - q_s, x_t - q_t
    weight = _sample_weights(geo, q_s, q_t, ds, dt, spp)
    right, up, fwd = geo.right, geo.up, geo.fwd
    origin = (
        geo.centers[k] + fwd * geo.dist + x_s[:, None] * right[None, :] + x_t[:, None] * up[None, :]
    )
    direction = ds[:, None] * right + dt[:, None] * up + geo.dist * fwd
    j = plane.hit_texel(origin, direction)
    ok = (j >= 0) & (weight > 0)
    return texel[ok].astype(np.int64) * plane.resolution**2 + j[ok], weight[ok]


def _csr_operator(key: np.ndarray, val: np.ndarray, shape: tuple[int, int]) -> torch.Tensor:
    """Sum the samples' weights per entry of ``W`` into a torch sparse CSR float32 matrix.

    Args:
        key: ``(n,)`` flat index ``row * shape[1] + col`` per sample (int64).
        val: ``(n,)`` weight per sample.
        shape: ``(mask texels, plane texels)``.
    """
    n_rows_w, n_img = shape
    uniq, inv = np.unique(key, return_inverse=True)
    summed = np.bincount(inv, weights=val, minlength=len(uniq))
    row_idx, col_idx = np.divmod(uniq, n_img)
    crow = np.zeros(n_rows_w + 1, dtype=np.int64)
    np.add.at(crow, row_idx + 1, 1)
    crow = np.cumsum(crow)
    with warnings.catch_warnings():  # "sparse CSR support is in beta"
        warnings.simplefilter("ignore", UserWarning)
        return torch.sparse_csr_tensor(
            torch.from_numpy(crow),
            torch.from_numpy(col_idx.astype(np.int64)),
            torch.from_numpy(summed.astype(np.float32)),
            size=(n_rows_w, n_img),
            check_invariants=True,
        )


def build_plane_transport(
    plane: PlaneGeometry,
    camera: FreeformCamera,
    *,
    spp: int = DEFAULT_OPERATOR_SPP,
    seed: int = 0,
) -> PlaneTransport:
    """Estimate ``W`` of ``camera`` seeing ``plane`` with ``render_transport``'s estimator.

    Per mask texel ``(k, v, u)``, ``spp`` pairs ``(x, q)``, stratified over the
    texel's samples (:func:`_stratified_samples`): ``x`` uniform in the
    texel, ``q`` uniform on the detector or, with probability
    :func:`~mincam_render.render.transport.cosine_sampling_fraction`, through a
    cosine-weighted direction from ``x``; the ray from ``x`` along ``x - q``
    adds ``A_t d^2 / |x-q|^4 f(theta) / p(q) / spp`` to ``W`` at the plane texel it
    hits. Computed in float64 numpy, in chunks of ~2M samples.

    Args:
        plane: the emitting plane (:meth:`PlaneGeometry.of` a patches family).
        camera: detector geometry and pose (the parallax of each detector included).
        spp: samples per mask texel, in [1, 2^20].
        seed: seed of numpy's generator, >= 0.

    Returns:
        The operator.

    Raises:
        ValueError: bad ``spp`` or ``seed``.
    """
    _check_operator_args(spp, seed)
    geo = _OperatorGeometry.of(camera)
    n_rows_w = camera.num_detectors * geo.rows * geo.cols
    rng = np.random.default_rng([seed, 0x9E37])
    texels_per_chunk = max(1, _SAMPLES_PER_CHUNK // spp)
    entries: list[np.ndarray] = []
    values: list[np.ndarray] = []
    for start in range(0, n_rows_w, texels_per_chunk):
        texel = np.repeat(np.arange(start, min(start + texels_per_chunk, n_rows_w)), spp)
        key, weight = _chunk_entries(plane, geo, rng, texel, spp)
        entries.append(key)
        values.append(weight)
    matrix = _csr_operator(
        np.concatenate(entries), np.concatenate(values), (n_rows_w, plane.resolution**2)
    )
    return PlaneTransport(matrix=matrix, camera=camera, plane=plane, spp=spp, seed=seed)


def radiance_images(family: PatchesFamily, frames: Sequence[int]) -> np.ndarray:
    """Plane radiance images of ``frames``: what :meth:`PatchesFamily.set_frame` uploads.

    Returns:
        ``L[frame, row, col]`` float32 (W m^-2 sr^-1), a pure function of the
        family's seed and the frame index.
    """
    n = family.config.image_resolution
    out = np.empty((len(frames), n, n), dtype=np.float32)
    for i, f in enumerate(frames):
        out[i] = family.image(int(f))[0]
    return out


def linear_transport_batches(
    family: PatchesFamily,
    operator: PlaneTransport,
    frames: Sequence[int],
    *,
    batch: int = 2048,
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Transport images and labels of ``frames``, ``batch`` frames at a time.

    Yields:
        ``(T[b, detector, row, col]`` float32 (W), ``count[b, 1]`` float32``)``, in
        the order of ``frames``; ``T = W L`` of each frame's radiance image.
    """
    frames = list(frames)
    for s in range(0, len(frames), batch):
        chunk = frames[s : s + batch]
        imgs = np.empty(
            (len(chunk), operator.plane.resolution, operator.plane.resolution), np.float32
        )
        counts = np.empty((len(chunk), 1), np.float32)
        for i, f in enumerate(chunk):
            img, state = family.image(int(f))
            imgs[i] = img
            counts[i, 0] = state["count"]
        yield operator.apply(imgs), counts
