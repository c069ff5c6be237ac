r"""Trainable cameras: a minimalist camera of freeform pixels and a box-pixel baseline.

Both cameras map transport images ``T[batch, time, detector, row, col]`` (torch,
watts per unit transmittance, see :mod:`mincam_render.render.transport`) to task
outputs through the same :class:`Head` (paper Sec. 5: two hidden layers of 128
units, leaky ReLU with slope 0.1).

* :class:`MincamCamera` -- ``K`` mask logits -> the mask plane (plain torch, or the
  Dr.Jit op of :func:`~mincam_render.optics.maskplane.mask_power`) ->
  :func:`~mincam_render.optics.sensor.detector_voltage` (paper eqs. 3-5) -> head.
  Pixel ``j`` of the camera reads detector ``detectors[j]`` of the data, so a
  camera may use a subset of the rendered detectors (pruning) or reuse one
  detector's transport for several masks (more pixels than were rendered;
  this ignores the parallax between the reused and the real position, which is
  sub-texel for the 20 mm pitch at scene depths beyond ~1 m). A *signed*
  camera pairs its pixels (plus, minus) and feeds the head their differences:
  a signed measurement from printable masks, at two photodiodes a pixel.
* :class:`BaselineCamera` -- a traditional camera of ``R x C`` square pixels
  that box-integrate the light: the transport images averaged over the
  rendered detectors (approximating one central camera, the paper's auxiliary
  camera in the middle of the board) and box-summed into ``R x C`` pixels,
  then an 8-bit camera's read-out: a fixed exposure (set once from the
  training data so that the 99.5th percentile of pixel power maps to 255 DN),
  Gaussian read noise (1 DN), additive uniform quantisation noise of one DN
  (the usual differentiable model of rounding) and clipping to [0, 255].

Targets of COUNT and REGRESSION labels are standardised with the training
set's mean and standard deviation (buffers of the head) so that one learning
rate suits every task; :meth:`Head.predict` returns physical values.

Losses per :class:`~mincam_render.scenes.base.LabelKind`: mean squared
error for COUNT and REGRESSION (in standardised units), binary cross-entropy
with logits per element for BINARY; the total is their sum. A COUNT label may
instead be learned as a class ``0 .. n-1`` by cross-entropy (:class:`CountLoss`;
the paper's toy task, Sec. 5); its prediction is then the expected count under
the softmax (the posterior mean, which minimises the squared error the task is
scored by).

Temporal samples (windows of ``history`` frames) can be given as the frames they
use, ``T[frame, detector, row, col]``, and ``windows[batch, time]`` indices into
them: every frame's mask-plane product is computed once however many windows
share it (consecutive traffic windows share 29 of 30), then each window gets
its own gain and noise, exactly as if its frames had been stacked.
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Mapping, Sequence
from typing import cast

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from mincam_render.core.checks import check_int
from mincam_render.core.labels import LabelKind, LabelSpec
from mincam_render.learn.train_config import HIDDEN_UNITS, CountLoss
from mincam_render.optics.camera import FreeformCamera
from mincam_render.optics.fabrication_fused import fused_fabricated_transmittance
from mincam_render.optics.maskplane import (
    MaskPlaneBackend,
    logits_for_transmittance,
    mask_power,
    power_through,
    total_variation_per_texel,
    transmittance,
)
from mincam_render.optics.perturbation import PerturbationDraw
from mincam_render.optics.sensor import detector_voltage

log = logging.getLogger(__name__)

#: The paper's mask initialisation: transmittance ~ U(0.08, 0.12) (Sec. 5).
INIT_TRANSMITTANCE = (0.08, 0.12)
#: The head's activation slope (paper Sec. 5; its width: HIDDEN_UNITS).
LEAKY_SLOPE = 0.1
#: Training keeps mask logits in [-MAX_LOGIT, MAX_LOGIT]. At |logit| = 8 the
#: transmittance is (hi - lo) * sigmoid(-8) ~ 2e-4 from its printable limit (below
#: what a printer resolves) while sigmoid'(8) ~ 3e-4 keeps the mask gradient above
#: Adam's epsilon; at |logit| = 50 it is ~1e-22 and a saturated mask never moves again.
MAX_LOGIT = 8.0
#: 8-bit baseline camera read-out (not from the paper: a typical machine-vision
#: sensor at unit gain has ~1 DN of read noise).
BASELINE_BITS = 8
BASELINE_READ_NOISE_DN = 1.0
#: Percentile of training pixel power that the baseline's fixed exposure maps to full scale.
BASELINE_EXPOSURE_PERCENTILE = 99.5


def _as_5d(transport: torch.Tensor) -> torch.Tensor:
    """``T[batch, detector, row, col]`` -> ``T[batch, 1, detector, row, col]``; 5-D unchanged."""
    if transport.ndim == 4:
        return transport[:, None]
    if transport.ndim != 5:
        raise ValueError(
            f"transport has shape {tuple(transport.shape)}: expected (batch, detector, row, col) "
            "or (batch, time, detector, row, col)"
        )
    return transport


def temporal_features(features: torch.Tensor) -> torch.Tensor:
    """Flatten ``x[batch, time, feature]`` for the head; forward differences when time > 1.

    The paper (supplement, traffic) feeds the head a 1-s stack of measurements
    after forward differencing in time: ``x[t+1] - x[t]``.
    """
    if features.shape[1] > 1:
        features = features[:, 1:] - features[:, :-1]
    return features.reshape(features.shape[0], -1)


#: A training label spread below this (in the label's unit) counts as constant.
CONSTANT_LABEL_STD = 1e-6


def _label_scale(name: str, std: object) -> np.ndarray:
    """Standardising scale of a regression/count label: its training spread, 1 where constant.

    A label that never changes in training (no traffic in one direction) has no
    spread to divide by; flooring it at a tiny value made every validation error
    of that label explode (losses of order 1e14), so it is learned in its own
    unit instead, with a warning.
    """
    arr = np.asarray(std, np.float32)
    flat = arr < CONSTANT_LABEL_STD
    if np.any(flat):
        log.warning(
            "label %r is constant in the training split (spread %s): learned unscaled",
            name,
            np.array2string(arr, precision=3),
        )
    return np.where(flat, np.float32(1.0), arr)


class InputNorm(nn.BatchNorm1d):
    """A head's non-affine input standardisation (a ``BatchNorm1d``).

    In training it normalises by the batch's statistics, unless
    ``running_in_training`` is set: then by the running statistics of the
    batches before (the first batch sets them), which move towards every batch
    after. Robust training sets it: a batch is measured through one built
    camera, and its own statistics would remove that camera's per-pixel gain and
    offset errors exactly, a calibration no deployed camera gets (evaluation
    uses the running statistics).
    """

    def __init__(self, num_features: int) -> None:
        super().__init__(num_features, affine=False)
        self.running_in_training = False

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Standardised ``x`` ``[batch, features]`` or ``[batch, features, steps]``."""
        if not (self.training and self.running_in_training):
            return super().forward(x)
        mean, var, seen = self.running_mean, self.running_var, self.num_batches_tracked
        if mean is None or var is None or seen is None:  # tracked by BatchNorm1d's default
            raise RuntimeError("the input norm keeps no running statistics")
        first = int(seen) == 0
        if first:  # no statistics yet: the first batch sets them
            self._update(x, 1.0)
        out = F.batch_norm(x, mean.clone(), var.clone(), None, None, False, 0.0, self.eps)
        if not first:
            self._update(x, self.momentum or 0.1)
        return out

    @torch.no_grad()
    def _update(self, x: torch.Tensor, momentum: float) -> None:
        """Move the running statistics towards the batch's by ``momentum``."""
        F.batch_norm(x.detach(), self.running_mean, self.running_var, None, None, True, momentum)
        self.num_batches_tracked.add_(1)  # type: ignore[union-attr]


class Head(nn.Module):
    """Inference network: input standardisation, 2 x ``hidden`` leaky-ReLU layers, label outputs.

    With a ``bottleneck`` of ``K``, the standardised inputs first pass through
    ``K`` learned linear combinations (signed, no bias), standardised again, so
    that the hidden layers see ``K`` numbers, as they do behind ``K`` freeform
    pixels. A box camera with such a head is ``K`` unconstrained linear
    measurements of its pixels: no printable range, no sign, no photodiode. The
    design protocol uses it to ask whether ``K`` linear measurements of the view
    can hold what its box pixels hold (``docs/design_protocol.md``).

    Args:
        in_features: number of inputs (pixels x time steps).
        label_specs: the task's labels; one output group of ``spec.size`` each.
        target_mean: ``{name: [size]}`` training-set mean of COUNT/REGRESSION labels.
        target_std: ``{name: [size]}`` training-set standard deviation (> 0).
        count_classes: ``{name: n}`` COUNT labels learned by cross-entropy over the
            counts ``0 .. n-1`` (n >= 2; ``n`` logits per element); the other
            COUNT labels are regressed (MSE). See :class:`CountLoss`.
        hidden: hidden width (the paper's :data:`HIDDEN_UNITS`).
        bottleneck: linear combinations of the inputs the hidden layers read
            (``K`` above); 0, the paper's head: the inputs themselves.

    Raises:
        ValueError: no labels, no inputs, a negative bottleneck, or
            ``count_classes`` naming a label that is not a COUNT label or giving
            fewer than 2 classes.

    """

    def __init__(
        self,
        in_features: int,
        label_specs: Sequence[LabelSpec],
        *,
        target_mean: Mapping[str, np.ndarray] | None = None,
        target_std: Mapping[str, np.ndarray] | None = None,
        count_classes: Mapping[str, int] | None = None,
        hidden: int = HIDDEN_UNITS,
        bottleneck: int = 0,
    ) -> None:
        super().__init__()
        check_int("bottleneck", bottleneck, 0)
        if in_features < 1:
            raise ValueError(f"in_features = {in_features}: need at least 1 input")
        self.label_specs = tuple(label_specs)
        if not self.label_specs:
            raise ValueError("label_specs is empty: a head needs at least one label")
        kinds = {s.name: s.kind for s in self.label_specs}
        self.count_classes: dict[str, int] = {}
        for name, n in (count_classes or {}).items():
            if kinds.get(name) is not LabelKind.COUNT:
                raise ValueError(
                    f"count_classes names {name!r}, which is not a COUNT label of this head "
                    f"(COUNT labels: {sorted(k for k, v in kinds.items() if v is LabelKind.COUNT)})"
                )
            self.count_classes[name] = check_int(f"count_classes[{name!r}]", n, 2, numpy=True)
        # Non-affine batch norm: the head sees unit-scale inputs whatever the mask
        # brightness or the scene's light level; it rescales, so SNR is untouched.
        self.input_norm = InputNorm(in_features)
        self.readout: nn.Module = nn.Identity()
        if bottleneck:
            self.readout = nn.Sequential(
                nn.Linear(in_features, bottleneck, bias=False), InputNorm(bottleneck)
            )
        self.body = nn.Sequential(
            nn.Linear(bottleneck or in_features, hidden),
            nn.LeakyReLU(LEAKY_SLOPE),
            nn.Linear(hidden, hidden),
            nn.LeakyReLU(LEAKY_SLOPE),
        )
        self.out = nn.Linear(hidden, sum(self.output_width(s) for s in self.label_specs))
        for s in self.label_specs:
            mean = np.zeros(s.size, np.float32)
            std = np.ones(s.size, np.float32)
            if s.kind is not LabelKind.BINARY:
                if target_mean is not None and s.name in target_mean:
                    mean = np.asarray(target_mean[s.name], np.float32).reshape(s.size)
                if target_std is not None and s.name in target_std:
                    std = _label_scale(s.name, target_std[s.name]).reshape(s.size)
            self.register_buffer(f"mean_{s.name}", torch.from_numpy(mean))
            self.register_buffer(f"std_{s.name}", torch.from_numpy(std))

    @property
    def in_features(self) -> int:
        """Number of inputs."""
        return int(self.input_norm.num_features)

    @property
    def bottleneck(self) -> int:
        """Linear combinations of the inputs the hidden layers read; 0: none."""
        return 0 if isinstance(self.readout, nn.Identity) else int(self.first_layer.out_features)

    @property
    def first_layer(self) -> nn.Linear:
        """The linear layer that reads the standardised inputs (the bottleneck's, if any)."""
        if isinstance(self.readout, nn.Identity):
            return cast(nn.Linear, self.body[0])
        return cast(nn.Linear, cast(nn.Sequential, self.readout)[0])

    @property
    def fan_in(self) -> int:
        """Inputs of one unit of the first layer (sets the learning rate): every input."""
        return self.in_features

    def count_loss(self, name: str) -> CountLoss:
        """How label ``name`` is learned if it is a COUNT label."""
        return CountLoss.CROSS_ENTROPY if name in self.count_classes else CountLoss.MSE

    def output_width(self, spec: LabelSpec) -> int:
        """Raw outputs of one label: ``size``, or ``size * classes`` for a classified count."""
        return spec.size * self.count_classes.get(spec.name, 1)

    def forward(self, x: torch.Tensor) -> dict[str, torch.Tensor]:
        """Raw outputs ``{name: [batch, width]}``: standardised values or logits.

        BINARY labels give one logit per element; a classified count gives class
        logits ``[batch, size * classes]`` (element-major, see :meth:`class_logits`).
        """
        y = self.out(self.features(x))
        return dict(
            zip(
                [s.name for s in self.label_specs],
                torch.split(y, [self.output_width(s) for s in self.label_specs], dim=1),
                strict=True,
            )
        )

    def features(self, x: torch.Tensor) -> torch.Tensor:
        """Hidden features ``[batch, hidden]`` of inputs ``x[batch, in_features]``."""
        return self.body(self.readout(self.input_norm(x)))

    def normalise_by_running_statistics(self, on: bool) -> None:
        """Set every input norm's ``running_in_training`` (:class:`InputNorm`)."""
        for norm in self.modules():
            if isinstance(norm, InputNorm):
                norm.running_in_training = on

    def input_running_mean(self) -> torch.Tensor:
        """``[in_features]`` running mean of every input (what pruning holds a pixel at)."""
        mean = self.input_norm.running_mean
        if mean is None:  # BatchNorm1d tracks running statistics by default
            raise RuntimeError("the head's input norm keeps no running mean")
        return mean

    def class_logits(self, name: str, outputs: torch.Tensor) -> torch.Tensor:
        """Raw outputs of a classified count -> logits ``[batch, size, classes]``."""
        return outputs.reshape(outputs.shape[0], -1, self.count_classes[name])

    def standardise(self, name: str, value: torch.Tensor) -> torch.Tensor:
        """Physical label -> the head's output units (identity for BINARY)."""
        return (value - getattr(self, f"mean_{name}")) / getattr(self, f"std_{name}")

    def predict(self, outputs: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """Raw outputs -> physical predictions: values (COUNT, REGRESSION), P(state=1) (BINARY)."""
        pred = {}
        for s in self.label_specs:
            y = outputs[s.name]
            if s.kind is LabelKind.BINARY:
                pred[s.name] = torch.sigmoid(y)
            elif s.name in self.count_classes:
                p = torch.softmax(self.class_logits(s.name, y), dim=-1)
                counts = torch.arange(p.shape[-1], dtype=p.dtype, device=p.device)
                pred[s.name] = p @ counts  # expected count, [batch, size]
            else:
                pred[s.name] = y * getattr(self, f"std_{s.name}") + getattr(self, f"mean_{s.name}")
        return pred


def task_loss(
    head: Head, outputs: Mapping[str, torch.Tensor], labels: Mapping[str, torch.Tensor]
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """Sum over labels of MSE (COUNT, REGRESSION; standardised) or BCE with logits (BINARY).

    A COUNT label in ``head.count_classes`` uses the cross-entropy of its class
    logits against the count (rounded, clipped to the classes), mean over elements.

    Args:
        head: supplies the label specs and the target standardisation.
        outputs: ``{name: [batch, size]}`` raw head outputs.
        labels: ``{name: [batch, size]}`` physical labels (0/1 for BINARY).

    Returns:
        ``(total, {name: loss})``, scalars.

    """
    parts = {}
    for s in head.label_specs:
        if s.name not in labels:
            raise KeyError(f"labels lack {s.name!r}; have {sorted(labels)}")
        y = labels[s.name].to(outputs[s.name].dtype)
        if s.kind is LabelKind.BINARY:
            parts[s.name] = F.binary_cross_entropy_with_logits(outputs[s.name], y)
        elif s.name in head.count_classes:
            logits = head.class_logits(s.name, outputs[s.name])
            n = logits.shape[-1]
            target = torch.clamp(torch.round(y), 0, n - 1).long()
            parts[s.name] = F.cross_entropy(logits.reshape(-1, n), target.reshape(-1))
        else:
            parts[s.name] = F.mse_loss(outputs[s.name], head.standardise(s.name, y))
    return torch.stack(list(parts.values())).sum(), parts


class CameraModel(nn.Module):
    """A camera feeding a :class:`Head`: subclasses define ``measure`` (pixel outputs)."""

    head: Head

    def measure(
        self,
        transport: torch.Tensor,
        *,
        windows: torch.Tensor | None = None,
        frame_scales: torch.Tensor | None = None,
        gain: torch.Tensor | None = None,
        noise: bool = True,
        generator: torch.Generator | None = None,
        draw: PerturbationDraw | None = None,
    ) -> torch.Tensor:
        """Pixel outputs ``[batch, time, pixel]``.

        Args:
            transport: ``T[batch, (time,) detector, row, col]`` (W), or with
                ``windows`` the frames ``T[frame, detector, row, col]`` they index.
            windows: ``[batch, time]`` long indices into ``transport``'s frames.
            frame_scales: ``[frame]`` factor from ``transport`` to watts (the
                stored values of a float16 dataset; see
                :func:`mincam_render.render.precision.encode_transport`): applied to the
                power, which is linear in the transport, not to every texel.
            gain: ``[batch]`` global gain per sample (augmentation).
            noise: add sensor noise.
            generator: random generator of the noise.
            draw: a built camera's deviations from the design
                (:class:`~mincam_render.optics.perturbation.PerturbationDraw`); None
                measures the camera as designed. Only a minimalist camera has them.

        """
        raise NotImplementedError

    def forward(
        self,
        transport: torch.Tensor,
        *,
        windows: torch.Tensor | None = None,
        frame_scales: torch.Tensor | None = None,
        gain: torch.Tensor | None = None,
        noise: bool = True,
        generator: torch.Generator | None = None,
        draw: PerturbationDraw | None = None,
    ) -> dict[str, torch.Tensor]:
        """Raw head outputs ``{name: [batch, size]}`` (arguments as :meth:`measure`)."""
        v = self.measure(
            transport,
            windows=windows,
            frame_scales=frame_scales,
            gain=gain,
            noise=noise,
            generator=generator,
            draw=draw,
        )
        return self.head(temporal_features(v))


def _per_window(
    frames: torch.Tensor, windows: torch.Tensor | None, frame_scales: torch.Tensor | None
) -> torch.Tensor:
    """``x[frame, ...]`` (times ``frame_scales``) -> ``x[batch, time, ...]`` via ``windows``."""
    if frame_scales is not None:
        frames = frames * frame_scales.reshape(-1, *(1,) * (frames.ndim - 1))
    if windows is None:
        return frames.unsqueeze(1)
    b, h = windows.shape
    return frames.index_select(0, windows.reshape(-1)).reshape(b, h, *frames.shape[1:])


def _frames_of(transport: torch.Tensor, windows: torch.Tensor | None) -> torch.Tensor:
    """The frames ``T[frame, detector, row, col]`` to measure (5-D batches flattened)."""
    if transport.ndim == 4:  # frames already (the hot path: no view, no reshape)
        return transport
    if windows is not None:
        raise ValueError(
            f"with windows, transport has shape {tuple(transport.shape)}: expected "
            "(frame, detector, row, col)"
        )
    t = _as_5d(transport)
    return t.reshape(-1, *t.shape[2:])


def _windows_for(transport: torch.Tensor, windows: torch.Tensor | None) -> torch.Tensor | None:
    """Window indices for a 5-D batch ``T[batch, time, ...]`` flattened by :func:`_frames_of`."""
    if windows is not None or transport.ndim == 4:
        return windows
    b, h = transport.shape[:2]
    return torch.arange(b * h, device=transport.device).reshape(b, h)


class MincamCamera(CameraModel):
    """A minimalist camera: trainable masks, the detector model, and a head.

    Args:
        camera: geometry, electronics and printable transmittance range.
        head: inference network with ``len(detectors) * max(history - 1, 1)`` inputs.
        detectors: data detector read by each pixel (default: all of ``camera``).
        sensor_model: apply :func:`detector_voltage` (noise, saturation); False
            feeds the head noiseless power scaled to volts (supplement A's ablation).
        history: frames per sample (1 = static task; 30 for traffic).
        init_seed: seed of the U(0.08, 0.12) mask initialisation.
        mask_plane: plain torch (default; for torch transport) or the Dr.Jit op.
        mask_block: masks parameterised in blocks of ``mask_block`` x ``mask_block``
            texels: the initialisation is drawn per block and every gradient is
            averaged over its block, so (Adam being per-element and the logits'
            projection a clamp) the texels of a block stay equal through training;
            1: every texel free.
        signed: pixels ``2j`` and ``2j + 1`` (photodiodes, masks) form signed
            pixel ``j``: its output is the first's reading minus the second's, each
            read by its own detector electronics (noise, saturation, ADC) and
            subtracted digitally. The head reads ``len(detectors) / 2`` signed
            outputs; a difference amplifier (one read noise for the pair) is not
            modelled.

    Raises:
        ValueError: no pixels, a head of the wrong width, a ``mask_block`` that
            does not divide the mask resolution, or an odd number of pixels signed.

    """

    detectors: torch.Tensor  # buffer: [pixel] detector index of each pixel

    def __init__(
        self,
        camera: FreeformCamera,
        head: Head,
        *,
        detectors: Sequence[int] | None = None,
        sensor_model: bool = True,
        history: int = 1,
        init_seed: int = 0,
        mask_plane: MaskPlaneBackend = MaskPlaneBackend.TORCH,
        mask_block: int = 1,
        signed: bool = False,
    ) -> None:
        super().__init__()
        self.camera = camera
        self.mask_plane = MaskPlaneBackend(mask_plane)
        dets = tuple(range(camera.num_detectors)) if detectors is None else tuple(detectors)
        if not dets:
            raise ValueError("detectors is empty: a minimalist camera needs at least one pixel")
        self.register_buffer("detectors", torch.tensor(dets, dtype=torch.long))
        self.signed = bool(signed)
        if self.signed and len(dets) % 2:
            raise ValueError(
                f"{len(dets)} pixels signed: a signed pixel is a pair (plus, minus) of them"
            )
        # every rendered detector once, in order: no gather of the transport needed
        self._identity_detectors = dets == tuple(range(camera.num_detectors))
        self.sensor_model = bool(sensor_model)
        self.history = int(history)
        rows, cols = camera.mask_resolution
        b = self.mask_block = check_int("mask_block", mask_block, 1, numpy=True)
        if rows % b or cols % b:
            raise ValueError(
                f"mask_block = {b} texels: must divide the mask resolution {rows}x{cols}"
            )
        g = torch.Generator().manual_seed(int(init_seed))
        lo, hi = INIT_TRANSMITTANCE
        m0 = lo + (hi - lo) * torch.rand((len(dets), rows // b, cols // b), generator=g)
        m0 = m0.repeat_interleave(b, dim=1).repeat_interleave(b, dim=2)
        self.logits = nn.Parameter(logits_for_transmittance(m0, camera.transmittance_range))
        if b > 1:
            self.logits.register_hook(functools.partial(block_mean, block=b))
        expected = self.num_outputs * max(self.history - 1, 1)
        if head.in_features != expected:
            raise ValueError(
                f"head has {head.in_features} inputs; this camera gives {expected} "
                f"({self.num_outputs} outputs x {max(self.history - 1, 1)} time steps)"
            )
        self.head = head

    @property
    def num_pixels(self) -> int:
        """Number of freeform pixels ``K`` (masks and photodiodes; two per signed pixel)."""
        return int(self.detectors.numel())

    @property
    def num_outputs(self) -> int:
        """Outputs the head reads per frame: ``K``, or ``K / 2`` signed pixels."""
        return self.num_pixels // 2 if self.signed else self.num_pixels

    def transmittance(self) -> torch.Tensor:
        """``M[pixel, row, col]`` in the printable range (torch, differentiable)."""
        return transmittance(self.logits, self.camera.transmittance_range)

    def project_logits_(self) -> None:
        """Clamp the logits in place to ``[-MAX_LOGIT, MAX_LOGIT]`` (NaN-free masks stay so)."""
        # in place on a detached view: no grad-mode switch (a no_grad block costs
        # about as much as the clamp itself at every step)
        self.logits.detach().clamp_(-MAX_LOGIT, MAX_LOGIT)

    def mask_penalty(self, tv_weight: float, logit_decay: float) -> torch.Tensor:
        """Priors on the masks (torch scalar, differentiable): smoothness and logit decay.

        ``tv_weight`` times the total variation per texel of the transmittance
        (:func:`~mincam_render.optics.maskplane.total_variation_per_texel`) plus
        ``logit_decay`` times the mean squared logit.
        """
        penalty = self.logits.new_zeros(())
        if tv_weight:
            penalty = penalty + tv_weight * total_variation_per_texel(self.transmittance())
        if logit_decay:
            penalty = penalty + logit_decay * self.logits.square().mean()
        return penalty

    def fabricated_transmittance(self, draw: PerturbationDraw) -> torch.Tensor:
        """``M[pixel, row, col]`` of the masks as built by ``draw`` (torch, differentiable once).

        One autograd node (:mod:`~mincam_render.optics.fabrication_fused`).
        """
        cam = self.camera
        return fused_fabricated_transmittance(
            self.logits, cam.transmittance_range, draw, cam.texel_size_m, camera=cam
        )

    def power(self, frames: torch.Tensor, draw: PerturbationDraw | None = None) -> torch.Tensor:
        """``P[frame, pixel]`` (W) of ``T[frame, detector, row, col]`` through the masks.

        With ``draw``, through the masks as built (plain torch mask plane).
        """
        if not self._identity_detectors:
            frames = frames.index_select(1, self.detectors)
        if draw is not None:
            return power_through(frames, self.fabricated_transmittance(draw))
        if self.mask_plane is MaskPlaneBackend.DRJIT:
            return mask_power(
                frames, self.logits, self.camera.transmittance_range, backend=self.mask_plane
            )
        if frames.shape[1:] != self.logits.shape:
            raise ValueError(
                f"transport frames have (detector, row, col) = {tuple(frames.shape[1:])}; "
                f"the masks are {tuple(self.logits.shape)}"
            )
        return power_through(frames, self.transmittance())

    def measure(
        self,
        transport: torch.Tensor,
        *,
        windows: torch.Tensor | None = None,
        frame_scales: torch.Tensor | None = None,
        gain: torch.Tensor | None = None,
        noise: bool = True,
        generator: torch.Generator | None = None,
        draw: PerturbationDraw | None = None,
    ) -> torch.Tensor:
        """Pixel outputs ``[batch, time, output]`` (V); arguments as :meth:`CameraModel.measure`.

        Without the sensor model: noiseless power x responsivity x gain (V, unsaturated).
        A ``draw`` also scales each pixel's power by its gain mismatch and adds its
        output offset (V). A signed camera's outputs are its pairs' differences.
        """
        v = self._readings(transport, windows, frame_scales, gain, noise, generator, draw)
        return v[..., 0::2] - v[..., 1::2] if self.signed else v

    def _readings(
        self,
        transport: torch.Tensor,
        windows: torch.Tensor | None,
        frame_scales: torch.Tensor | None,
        gain: torch.Tensor | None,
        noise: bool,
        generator: torch.Generator | None,
        draw: PerturbationDraw | None,
    ) -> torch.Tensor:
        """Every photodiode's reading ``[batch, time, pixel]`` (V), as :meth:`measure`."""
        frames = _frames_of(transport, windows)
        windows = _windows_for(transport, windows)
        power = _per_window(self.power(frames, draw), windows, frame_scales)
        if gain is not None:
            power = power * gain.reshape(-1, 1, 1)
        offset = None
        if draw is not None:
            if not (draw.gain == 1.0).all():
                power = power * torch.as_tensor(draw.gain, dtype=power.dtype, device=power.device)
            if draw.offset_v.any():
                offset = torch.as_tensor(draw.offset_v, dtype=power.dtype, device=power.device)
        e = self.camera.electronics
        if not self.sensor_model:
            v = power * (e.responsivity_a_per_w * e.gain_v_per_a)
            return v if offset is None else v + offset
        return detector_voltage(power, e, noise=noise, generator=generator, offset_v=offset)


def block_mean(grad: torch.Tensor, *, block: int) -> torch.Tensor:
    """``grad[..., row, col]`` averaged over ``block`` x ``block`` tiles, tiled back (torch)."""
    *lead, rows, cols = grad.shape
    tiles = grad.reshape(*lead, rows // block, block, cols // block, block)
    mean = tiles.mean(dim=(-3, -1), keepdim=True).expand_as(tiles)
    return mean.reshape(grad.shape)


@functools.lru_cache(maxsize=64)
def area_weights(texels: int, pixels: int) -> torch.Tensor:
    """``W[pixel, texel]``: the length (in texels) of texel ``j`` inside pixel ``i`` (float64).

    Pixel ``i`` spans ``[i, i + 1) * texels / pixels`` of the texel axis, so each
    texel's column sums to 1 (every texel's power goes somewhere, once) and each
    pixel's row sums to ``texels / pixels`` (equal areas).
    """
    edges = torch.arange(pixels + 1, dtype=torch.float64) * (texels / pixels)
    left = torch.arange(texels, dtype=torch.float64)
    lo = torch.maximum(edges[:-1, None], left[None, :])
    hi = torch.minimum(edges[1:, None], left[None, :] + 1.0)
    return torch.clamp(hi - lo, min=0.0)


def box_pixels(image: torch.Tensor, grid: tuple[int, int]) -> torch.Tensor:
    """Box-sum ``image[..., row, col]`` into ``grid = (R, C)`` pixels (sums power; torch).

    Area-correct for any grid: a pixel boundary inside a texel splits that
    texel's power by area (:func:`area_weights`), so the total power is
    conserved and a uniform image gives equal pixels (e.g. 32 texels onto 28
    columns). Even divisions are plain box sums.
    """
    rows, cols = image.shape[-2:]
    r, c = grid
    if not (1 <= r <= rows and 1 <= c <= cols):
        raise ValueError(f"baseline grid {r}x{c} must lie within the transport's {rows}x{cols}")
    lead = image.shape[:-2]
    if rows % r == 0 and cols % c == 0:
        flat = image.reshape(-1, 1, rows, cols)
        pooled = F.adaptive_avg_pool2d(flat, (r, c)) * (rows * cols / (r * c))
        return pooled.reshape(*lead, r, c)
    wr = area_weights(rows, r).to(image.dtype)
    wc = area_weights(cols, c).to(image.dtype)
    return wr @ image @ wc.T


class BaselineCamera(CameraModel):
    """A traditional ``R x C`` camera (box pixels, 8-bit read-out) feeding a :class:`Head`.

    Args:
        grid: ``(R, C)`` pixels.
        head: inference network with ``R * C * max(history - 1, 1)`` inputs.
        exposure_w: pixel power mapped to 255 DN (W), see :meth:`exposure_from`.
        history: frames per sample.
        read_noise_dn: Gaussian read noise (DN).

    """

    exposure_w: torch.Tensor  # buffer: scalar power (W) that reads full scale

    def __init__(
        self,
        grid: tuple[int, int],
        head: Head,
        *,
        exposure_w: float,
        history: int = 1,
        read_noise_dn: float = BASELINE_READ_NOISE_DN,
    ) -> None:
        super().__init__()
        self.grid = (int(grid[0]), int(grid[1]))
        if not exposure_w > 0:
            raise ValueError(f"exposure_w = {exposure_w!r} W: need a positive pixel power")
        self.register_buffer("exposure_w", torch.tensor(float(exposure_w)))
        self.history = int(history)
        self.read_noise_dn = float(read_noise_dn)
        expected = self.num_pixels * max(self.history - 1, 1)
        if head.in_features != expected:
            raise ValueError(f"head has {head.in_features} inputs; this camera gives {expected}")
        self.head = head

    @property
    def num_pixels(self) -> int:
        """``R * C``."""
        return self.grid[0] * self.grid[1]

    @staticmethod
    def exposure_from(transport: np.ndarray, grid: tuple[int, int]) -> float:
        """Fixed exposure (W at 255 DN) from training transport ``[N, K, R, C]`` (numpy)."""
        sample = np.asarray(transport[: min(len(transport), 2048)], np.float32)
        pix = box_pixels(torch.from_numpy(sample).mean(dim=1), grid).numpy()
        value = float(np.percentile(pix, BASELINE_EXPOSURE_PERCENTILE))
        return value if value > 0 else 1.0

    def measure(
        self,
        transport: torch.Tensor,
        *,
        windows: torch.Tensor | None = None,
        frame_scales: torch.Tensor | None = None,
        gain: torch.Tensor | None = None,
        noise: bool = True,
        generator: torch.Generator | None = None,
        draw: PerturbationDraw | None = None,
    ) -> torch.Tensor:
        """Pixel values ``[batch, time, R*C]`` in DN / 255 (0-1); arguments as in the base.

        Raises:
            ValueError: a ``draw`` was given (it describes freeform pixels).
        """
        if draw is not None:
            raise ValueError(
                "perturbation draws describe freeform pixels (masks, diodes); a baseline "
                "camera has none"
            )
        frames = _frames_of(transport, windows)
        windows = _windows_for(transport, windows)
        pix = box_pixels(frames.mean(dim=1), self.grid).reshape(len(frames), self.num_pixels)
        pix = _per_window(pix, windows, frame_scales)
        if gain is not None:
            pix = pix * gain.reshape(-1, 1, 1)
        full = 2**BASELINE_BITS - 1
        dn = pix / self.exposure_w * full
        if noise:
            kw = {"dtype": dn.dtype, "device": dn.device, "generator": generator}
            dn = dn + self.read_noise_dn * torch.randn(dn.shape, **kw)
            dn = dn + (torch.rand(dn.shape, **kw) - 0.5)
        return torch.clamp(dn, 0.0, float(full)) / full


#: A trainable camera of either kind.
Model = MincamCamera | BaselineCamera
