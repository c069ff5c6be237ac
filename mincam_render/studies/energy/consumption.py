r"""What a frame costs: readout, inference head, radio; and what waiting between frames costs.

A frame of a minimalist camera of ``K`` pixels: the MCU wakes from Stop2, reads
the ``K`` amplified photodiodes through the multiplexer with its ADC, runs the
inference head (optional), sends the samples (and outputs) over BLE, and sleeps.
Between frames the amplifiers, the multiplexer and the sleeping MCU draw a
static current. All energies are at the load's supply rail (J); the converter
from the capacitor is applied by the storage simulation.

.. math::

    P_{load}(f) = P_{static} + f \, E_{frame}

A conventional module (:func:`module_frame_budget`) pays its sensor's power, the
MCU's time while the mode's pixels arrive, binning them to the matched grid, the
head on the grid, and the radio for the grid's pixels.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from mincam_render.studies.energy.config import CameraModuleConfig, ConsumptionConfig

if TYPE_CHECKING:
    from torch import nn

    from mincam_render.core.labels import LabelSpec
    from mincam_render.learn.models import Head


@dataclass(frozen=True, kw_only=True)
class FrameBudget:
    """Energy of one frame and the static power between frames, at the supply rail.

    Args:
        pixels: measurements per frame (freeform pixels, or grid pixels of a module).
        wake_j: waking the MCU (J).
        readout_j: reading the pixels (MCU, ADC; or the module's sensor and capture) (J).
        compute_j: the inference head (and binning for a module) (J).
        radio_j: BLE packets of the payload (J).
        static_w: drawn all the time, running or not (W).
        active_s: time the MCU is awake per frame (s): 1/active_s bounds the frame rate.
        payload_bytes: bytes sent per frame.
        packets: BLE packets per frame.
        head_flops: floating-point operations of the head per frame.
    """

    pixels: int
    wake_j: float
    readout_j: float
    compute_j: float
    radio_j: float
    static_w: float
    active_s: float
    payload_bytes: int
    packets: int
    head_flops: int

    @property
    def energy_per_frame_j(self) -> float:
        """``wake + readout + compute + radio`` (J)."""
        return self.wake_j + self.readout_j + self.compute_j + self.radio_j

    @property
    def max_fps(self) -> float:
        """The frame rate at which the MCU never sleeps (1/s)."""
        return 1.0 / self.active_s

    def power_w(self, fps: float) -> float:
        """Mean load power at ``fps`` frames per second (W)."""
        return self.static_w + fps * self.energy_per_frame_j

    def sustainable_fps(self, available_w: float) -> float:
        """Frame rate ``available_w`` (W at the rail) sustains, in [0, max_fps] (1/s)."""
        fps = (available_w - self.static_w) / self.energy_per_frame_j
        return min(max(fps, 0.0), self.max_fps)


def head_flops(head: nn.Module) -> int:
    """Floating-point operations of one forward pass of ``head`` (batch of one).

    Linear layers: ``2 in out`` (multiply-add) + ``out`` (bias); a LeakyReLU one per
    element it sees; a non-affine BatchNorm two per input (subtract, scale).

    Args:
        head: a torch module made of ``Linear``, ``LeakyReLU`` and ``BatchNorm1d``.
    """
    from torch import nn

    flops, width = 0, 0
    for m in head.modules():
        if isinstance(m, nn.Linear):
            flops += 2 * m.in_features * m.out_features + m.out_features
            width = m.out_features
        elif isinstance(m, nn.LeakyReLU):
            flops += width
        elif isinstance(m, nn.BatchNorm1d):
            flops += 2 * m.num_features
    return flops


def paper_head(pixels: int, labels: Sequence[LabelSpec]) -> Head:
    """The paper's head (2 x 128 leaky-ReLU) for ``pixels`` inputs and ``labels`` outputs."""
    from mincam_render.learn.models import Head

    return Head(pixels, labels)


def radio_cost(payload_bytes: int, c: ConsumptionConfig) -> tuple[float, int, float]:
    """``(energy J, packets, time s)`` of sending ``payload_bytes`` in one BLE connection event.

    Each packet: TX of payload + overhead bytes at ``ble_bit_rate_bps``, then the
    central's acknowledgement at RX current; once per event: start-up at run current.
    Nothing to send costs nothing.
    """
    if payload_bytes <= 0:
        return 0.0, 0, 0.0
    packets = math.ceil(payload_bytes / c.ble_max_payload_bytes)
    tx_s = 8 * (payload_bytes + packets * c.ble_packet_overhead_bytes) / c.ble_bit_rate_bps
    ack_s = packets * c.ble_ack_time_s
    charge = (
        c.ble_tx_current_a * tx_s
        + c.ble_rx_current_a * ack_s
        + c.run_current_a * c.ble_event_overhead_s
    )
    return c.supply_voltage_v * charge, packets, tx_s + ack_s + c.ble_event_overhead_s


def mincam_frame_budget(
    c: ConsumptionConfig, *, pixels: int, flops: int, outputs: int
) -> FrameBudget:
    """The frame budget of a minimalist camera of ``pixels`` freeform pixels.

    Args:
        c: the electronics.
        pixels: freeform pixels read per frame (>= 1).
        flops: the head's FLOPs per frame (ignored unless ``c.head_on_device``).
        outputs: the head's outputs, sent when it runs on the device.

    Raises:
        ValueError: ``pixels < 1``.
    """
    if pixels < 1:
        raise ValueError(f"pixels = {pixels!r}: allowed an integer >= 1")
    v, run = c.supply_voltage_v, c.run_current_a
    flops = flops if c.head_on_device else 0
    compute_s = flops * c.cycles_per_flop / c.mcu_clock_hz
    readout_s = pixels * c.readout_time_per_pixel_s
    payload = _payload_bytes(c, pixels * c.sample_bytes, outputs)
    radio_j, packets, radio_s = radio_cost(payload, c)
    return FrameBudget(
        pixels=pixels,
        wake_j=v * run * c.wakeup_time_s,
        readout_j=v * (run + c.adc_current_a) * readout_s,
        compute_j=v * run * compute_s,
        radio_j=radio_j,
        static_w=v * (c.mcu_sleep_current_a + pixels * c.amplifier_current_a + c.mux_current_a),
        active_s=c.wakeup_time_s + readout_s + compute_s + radio_s,
        payload_bytes=payload,
        packets=packets,
        head_flops=flops,
    )


def _payload_bytes(c: ConsumptionConfig, sample_bytes: int, outputs: int) -> int:
    """Bytes sent per frame: the samples and/or the head's outputs, as configured."""
    return (sample_bytes if c.send_samples else 0) + (
        outputs * c.output_bytes if c.head_on_device else 0
    )


def module_frame_budget(
    c: ConsumptionConfig,
    m: CameraModuleConfig,
    *,
    grid: tuple[int, int],
    flops: int,
    outputs: int,
) -> FrameBudget:
    """The frame budget of a conventional module read at its smallest mode and binned to ``grid``.

    The sensor's energy per frame is ``mode_power_w / mode_fps`` (its datasheet
    power scaled with frame rate); the MCU runs while the mode's pixels arrive
    (``pixel_rate_hz``), adds each into its grid cell (one FLOP a pixel), runs the
    head on the grid and sends the grid's pixels and/or the head's outputs.

    Raises:
        ValueError: a grid finer than the module's mode.
    """
    rows, cols = grid
    if rows * cols > m.mode_pixels[0] * m.mode_pixels[1] or min(rows, cols) < 1:
        raise ValueError(f"grid = {list(grid)}: must be >= 1 x 1 and within {list(m.mode_pixels)}")
    v, run = c.supply_voltage_v, c.run_current_a
    mode = m.mode_pixels[0] * m.mode_pixels[1]
    capture_s = mode / m.pixel_rate_hz
    flops = mode + (flops if c.head_on_device else 0)
    compute_s = flops * c.cycles_per_flop / c.mcu_clock_hz
    payload = _payload_bytes(c, rows * cols * m.pixel_bytes, outputs)
    radio_j, packets, radio_s = radio_cost(payload, c)
    return FrameBudget(
        pixels=rows * cols,
        wake_j=v * run * c.wakeup_time_s,
        readout_j=m.mode_power_w / m.mode_fps + v * run * capture_s,
        compute_j=v * run * compute_s,
        radio_j=radio_j,
        static_w=v * c.mcu_sleep_current_a,
        active_s=c.wakeup_time_s + capture_s + compute_s + radio_s,
        payload_bytes=payload,
        packets=packets,
        head_flops=flops,
    )
