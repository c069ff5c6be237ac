"""The self-powered budget's description: panel, storage, electronics, schedule, render.

Frozen, keyword-only dataclasses in SI units (m, m^2, s, W, A, V, F, Hz, J). Every
default comes from a component datasheet or is an assumption stated in its
``doc``; ``docs/energy.md`` cites each one, and ``scenes/energy.toml`` repeats
them as a file users copy and edit. :func:`load_energy_config` reads such a
file with :mod:`tomllib` (through :func:`mincam_render.core.config.load_toml`),
rejecting unknown keys, wrong types and out-of-range values with a
:class:`~mincam_render.core.config.ConfigError` naming the field.

No numpy, torch or Mitsuba import: the command line shows these defaults at once.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from mincam_render.core.config import ConfigError, Described, load_toml, spec
from mincam_render.core.package_data import shipped_path

#: The shipped description's file name among the package data (``scenes/`` in a clone).
ENERGY_TOML = "energy.toml"


@dataclass(frozen=True, kw_only=True)
class PanelConfig(Described):
    """The photovoltaic panel beside the camera board and its power path to the capacitor."""

    area_m2: float = spec(
        0.016872,  # 4 x 0.114 m x 0.037 m
        unit="m^2",
        range=(1e-6, 10.0),
        doc="active area: 4 x PowerFilm MP3-37 (114 x 37 mm each), as on the paper's prototype",
    )
    efficiency: float = spec(
        0.067,
        range=(1e-6, 1.0),
        doc="electrical W per W of visible-band light on the panel; amorphous silicon under "
        "white light (Panasonic Amorton AM-1815: 3.0 V x 42 uA at 200 lx on 58.1 x 48.6 mm)",
    )
    spectral_mismatch: float = spec(
        1.0,
        range=(0.0, 2.0),
        doc="multiplies efficiency for a light whose spectrum differs from the rating's",
    )
    mppt_efficiency: float = spec(
        0.80,
        range=(1e-6, 1.0),
        doc="harvester/charger efficiency, panel to capacitor (TI BQ25570 boost charger, "
        "about 80 % at 100 uW-1 mW input)",
    )
    offset_m: float = spec(
        0.05,
        unit="m",
        range=(0.0, 1.0),
        doc="panel centre below the board centre, along the board's -up axis",
    )
    tilt_deg: float = spec(
        0.0,
        unit="deg",
        range=(-90.0, 90.0),
        doc="panel normal tilted from the board's normal toward the board's up axis",
    )

    @property
    def electrical_efficiency(self) -> float:
        """Panel W to capacitor W per W of visible light: efficiency x mismatch x MPPT."""
        return self.efficiency * self.spectral_mismatch * self.mppt_efficiency


@dataclass(frozen=True, kw_only=True)
class StorageConfig(Described):
    """The supercapacitor bank and the converter from it to the load."""

    capacitance_f: float = spec(
        0.088, unit="F", range=(1e-6, 1000.0), doc="8 x 11 mF, the paper's prototype"
    )
    max_voltage_v: float = spec(
        3.3, unit="V", range=(0.1, 100.0), doc="rated voltage (Seiko CPH3225A, 11 mF, 3.3 V)"
    )
    brownout_voltage_v: float = spec(
        1.8,
        unit="V",
        range=(0.0, 100.0),
        doc="the load stops below this (STM32WB55 supply minimum 1.71 V)",
    )
    restart_voltage_v: float = spec(
        2.2,
        unit="V",
        range=(0.0, 100.0),
        doc="after a brown-out the load restarts at this voltage (hysteresis)",
    )
    initial_voltage_v: float = spec(
        1.8, unit="V", range=(0.0, 100.0), doc="capacitor voltage at midnight of the first day"
    )
    leakage_current_a: float = spec(
        8e-6,
        unit="A",
        range=(0.0, 1.0),
        doc="leakage at max_voltage_v (8 cells x ~1 uA); modelled as a resistance "
        "max_voltage_v / leakage_current_a",
    )
    converter_efficiency: float = spec(
        0.90, range=(1e-6, 1.0), doc="capacitor to load supply (the MCU's SMPS/regulator)"
    )

    def __post_init__(self) -> None:
        v_max = self.max_voltage_v
        for name in ("brownout_voltage_v", "restart_voltage_v", "initial_voltage_v"):
            if getattr(self, name) > v_max:
                raise ValueError(
                    f"{name} = {getattr(self, name)!r} V is above max_voltage_v = {v_max!r} V"
                )
        if self.restart_voltage_v < self.brownout_voltage_v:
            raise ValueError(
                f"restart_voltage_v = {self.restart_voltage_v!r} V is below "
                f"brownout_voltage_v = {self.brownout_voltage_v!r} V"
            )

    @property
    def usable_energy_j(self) -> float:
        """Energy between max_voltage_v and brownout_voltage_v: C (V_max^2 - V_bo^2) / 2 (J)."""
        c, v1, v0 = self.capacitance_f, self.max_voltage_v, self.brownout_voltage_v
        return 0.5 * c * (v1 * v1 - v0 * v0)

    @property
    def leakage_resistance_ohm(self) -> float:
        """``max_voltage_v / leakage_current_a`` (inf without leakage)."""
        return (
            self.max_voltage_v / self.leakage_current_a
            if self.leakage_current_a > 0
            else float("inf")
        )


@dataclass(frozen=True, kw_only=True)
class ConsumptionConfig(Described):
    """The minimalist camera's electronics: readout, multiplexer, MCU, BLE radio."""

    supply_voltage_v: float = spec(3.0, unit="V", range=(1.0, 5.5), doc="load supply rail")
    mcu_clock_hz: float = spec(
        64e6, unit="Hz", range=(1e3, 1e9), doc="STM32WB55 Cortex-M4 at its maximum 64 MHz"
    )
    mcu_run_current_a_per_hz: float = spec(
        53e-12,
        unit="A/Hz",
        range=(0.0, 1e-6),
        doc="STM32WB55 run mode, 53 uA/MHz (datasheet DS11929, SMPS on)",
    )
    mcu_sleep_current_a: float = spec(
        2.1e-6,
        unit="A",
        range=(0.0, 1e-1),
        doc="STM32WB55 Stop2 with RTC and full RAM retention, 2.1 uA (DS11929)",
    )
    wakeup_time_s: float = spec(
        10e-6, unit="s", range=(0.0, 1.0), doc="Stop2 to run, at run current (assumption)"
    )
    amplifier_current_a: float = spec(
        350e-9,
        unit="A",
        range=(0.0, 1e-1),
        doc="per pixel, always on: TI TLV521 nanopower op-amp quiescent current",
    )
    mux_current_a: float = spec(
        1e-6,
        unit="A",
        range=(0.0, 1e-1),
        doc="ADI ADG732 32:1 multiplexer supply current (typical), always on",
    )
    readout_time_per_pixel_s: float = spec(
        10e-6,
        unit="s",
        range=(1e-9, 1.0),
        doc="mux switch, settling and ADC sample + conversion per pixel (assumption)",
    )
    adc_current_a: float = spec(
        0.2e-3, unit="A", range=(0.0, 1.0), doc="ADC supply current while converting (assumption)"
    )
    cycles_per_flop: float = spec(
        1.0,
        unit="cycle/FLOP",
        range=(0.01, 1000.0),
        doc="Cortex-M4F fp32 multiply-accumulate with its loads: ~2 cycles per MAC",
    )
    head_on_device: bool = spec(
        True, doc="the MCU runs the inference head each frame and sends its outputs"
    )
    send_samples: bool = spec(
        True, doc="send the pixel samples each frame (the paper's prototype does)"
    )
    sample_bytes: int = spec(2, unit="B", range=(1, 8), doc="bytes per pixel sample (16-bit ADC)")
    output_bytes: int = spec(4, unit="B", range=(0, 64), doc="bytes per head output (fp32)")
    ble_tx_current_a: float = spec(
        5.2e-3, unit="A", range=(0.0, 1.0), doc="STM32WB55 radio TX at 0 dBm (DS11929)"
    )
    ble_rx_current_a: float = spec(
        4.5e-3, unit="A", range=(0.0, 1.0), doc="STM32WB55 radio RX (DS11929)"
    )
    ble_bit_rate_bps: float = spec(
        1e6, unit="bit/s", range=(1e3, 1e8), doc="BLE 1M PHY (2M halves air time)"
    )
    ble_packet_overhead_bytes: int = spec(
        17,
        unit="B",
        range=(0, 1000),
        doc="preamble 1 + access address 4 + header 2 + L2CAP 4 + ATT 3 + CRC 3",
    )
    ble_max_payload_bytes: int = spec(
        244, unit="B", range=(1, 65535), doc="ATT payload per packet with data length extension"
    )
    ble_ack_time_s: float = spec(
        230e-6,
        unit="s",
        range=(0.0, 1.0),
        doc="per packet at RX current: inter-frame space 150 us + the central's empty packet",
    )
    ble_event_overhead_s: float = spec(
        0.4e-3,
        unit="s",
        range=(0.0, 1.0),
        doc="per connection event at run current: radio start-up and stack (assumption)",
    )

    def __post_init__(self) -> None:
        if not (self.head_on_device or self.send_samples):
            raise ValueError("head_on_device = false and send_samples = false: nothing is sent")

    @property
    def run_current_a(self) -> float:
        """MCU current while running at ``mcu_clock_hz`` (A)."""
        return self.mcu_run_current_a_per_hz * self.mcu_clock_hz


@dataclass(frozen=True, kw_only=True)
class CameraModuleConfig(Described):
    """A conventional low-resolution camera module, for comparison at matched task error."""

    name: str = spec("Himax HM01B0", doc="the module")
    mode_pixels: tuple[int, int] = spec(
        (160, 120), unit="px", doc="smallest readout mode covering the grid: QQVGA"
    )
    mode_power_w: float = spec(
        1.1e-3, unit="W", range=(0.0, 10.0), doc="HM01B0 product brief: < 1.1 mW QQVGA at 30 fps"
    )
    mode_fps: float = spec(30.0, unit="1/s", range=(1e-3, 1e4), doc="frame rate of mode_power_w")
    pixel_rate_hz: float = spec(
        6e6,
        unit="px/s",
        range=(1e3, 1e10),
        doc="pixels per second into the MCU (8-bit bus); the MCU runs while they arrive",
    )
    pixel_bytes: int = spec(1, unit="B", range=(1, 8), doc="bytes per transmitted grid pixel")

    def __post_init__(self) -> None:
        if min(self.mode_pixels) < 1:
            raise ValueError(f"mode_pixels = {list(self.mode_pixels)}: both must be >= 1")


@dataclass(frozen=True, kw_only=True)
class LightSchedule(Described):
    """When one switchable light is on (local solar hours, [on_hour, off_hour))."""

    name: str = spec(doc="the light's name in the scene description")
    on_hour: float = spec(unit="h", range=(0.0, 24.0), doc="switched on")
    off_hour: float = spec(unit="h", range=(0.0, 24.0), doc="switched off (< on_hour: overnight)")


@dataclass(frozen=True, kw_only=True)
class ScheduleConfig(Described):
    """The simulated day: sampling, office lights, weather."""

    step_min: float = spec(
        15.0, unit="min", range=(1.0, 120.0), doc="irradiance sampled every step_min"
    )
    simulation_step_s: float = spec(
        60.0, unit="s", range=(0.1, 3600.0), doc="time step of the storage simulation"
    )
    lights_on_hour: float = spec(
        8.0, unit="h", range=(0.0, 24.0), doc="office hours: every light on from"
    )
    lights_off_hour: float = spec(18.0, unit="h", range=(0.0, 24.0), doc="...until")
    lights: tuple[LightSchedule, ...] = spec(
        default_factory=tuple, doc="per-light exceptions to the office hours"
    )
    overcast: float | None = spec(
        None, range=(0.0, 1.0), doc="replaces the scene's [daylight] overcast (0 clear, 1 overcast)"
    )

    def __post_init__(self) -> None:
        if abs(24 * 60 / self.step_min - round(24 * 60 / self.step_min)) > 1e-9:
            raise ValueError(f"step_min = {self.step_min!r} min: must divide 24 h evenly")

    def hours_on(self, name: str) -> tuple[float, float]:
        """``(on_hour, off_hour)`` of light ``name``."""
        for light in self.lights:
            if light.name == name:
                return light.on_hour, light.off_hour
        return self.lights_on_hour, self.lights_off_hour


@dataclass(frozen=True, kw_only=True)
class RenderConfig(Described):
    """How the panel's irradiance is rendered."""

    spp: int = spec(16384, range=(1, 1 << 24), doc="samples per batch of the irradiance meter")
    batches: int = spec(8, range=(2, 1024), doc="independent batches: their spread is the error")
    max_depth: int = spec(
        12,
        range=(2, 64),
        doc="path depth: the panel sees lit walls, so interreflections matter "
        "(depth 3 reads 26-32 % low in the workspace)",
    )
    seed: int = spec(0, range=(0, 2**31 - 1), doc="sampler seed of the first batch")


@dataclass(frozen=True, kw_only=True)
class EnergyConfig(Described):
    """Everything the self-powered budget needs besides the scene."""

    fps: float = spec(30.0, unit="1/s", range=(1e-3, 1e4), doc="frame rate simulated over the day")
    max_pixels: int = spec(24, range=(1, 1024), doc="pixel counts 1..max_pixels are evaluated")
    paper_threshold_lux: float = spec(
        600.0, unit="lx", range=(0.0, 1e6), doc="paper Sec. 6: 24 px at 30 fps above ~600 lux"
    )
    panel: PanelConfig = spec(default_factory=PanelConfig)
    storage: StorageConfig = spec(default_factory=StorageConfig)
    consumption: ConsumptionConfig = spec(default_factory=ConsumptionConfig)
    camera_module: CameraModuleConfig = spec(default_factory=CameraModuleConfig)
    schedule: ScheduleConfig = spec(default_factory=ScheduleConfig)
    render: RenderConfig = spec(default_factory=RenderConfig)


def load_energy_config(
    path: str | os.PathLike | None = None, overrides: dict | None = None
) -> EnergyConfig:
    """Read an energy description (TOML); ``None`` reads the shipped ``scenes/energy.toml``.

    Args:
        path: a TOML file whose tables are the fields of :class:`EnergyConfig`.
        overrides: nested dict replacing file values (e.g. ``{"render": {"spp": 64}}``).

    Raises:
        ConfigError: missing file, bad TOML, unknown key, wrong type or range; the
            message names the file and the field.
    """
    path = Path(path) if path is not None else shipped_path(ENERGY_TOML)
    if not path.is_file():
        raise ConfigError(f"{path}: energy description not found")
    return load_toml(EnergyConfig, path, overrides)
