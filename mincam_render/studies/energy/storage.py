r"""The supercapacitor between the panel and the load, stepped through a day.

State: the capacitor's energy :math:`E = C V^2 / 2`. Each step of ``dt`` seconds
with harvested power :math:`P_h` (W, into the capacitor, after the MPPT loss):

.. math::

    E' = E + (P_h - V^2 / R_{leak} - r P_{load} / \eta_{conv}) \, dt

where the load runs (:math:`r = 1`) while :math:`V` stays above the brown-out
voltage, and after a brown-out restarts only once :math:`V` reaches the restart
voltage. A step that would overfill the capacitor spills the excess; one that
would take a running load below brown-out runs it for the part of the step the
energy allows. Every joule is booked: harvested = stored change + consumed +
leaked + spilled, to floating-point rounding.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mincam_render.studies.energy.config import StorageConfig


@dataclass(frozen=True, kw_only=True)
class StorageTrace:
    """A simulated stretch of time.

    Args:
        time_s: step boundaries (s), shape (N + 1,).
        voltage_v: capacitor voltage at the boundaries (V), shape (N + 1,).
        running: fraction of each step the load ran, in [0, 1], shape (N,).
        harvested_j: energy into the capacitor over the whole trace (J).
        consumed_j: energy drawn by the load, converter loss included (J).
        leaked_j: energy lost to leakage (J).
        spilled_j: harvest refused by a full capacitor (J).
        capacitance_f: the capacitor (F), to turn voltages into energies.
    """

    time_s: np.ndarray
    voltage_v: np.ndarray
    running: np.ndarray
    harvested_j: float
    consumed_j: float
    leaked_j: float
    spilled_j: float
    capacitance_f: float

    @property
    def stored_j(self) -> np.ndarray:
        """Capacitor energy ``C V^2 / 2`` at the step boundaries (J), shape (N + 1,)."""
        return 0.5 * self.capacitance_f * self.voltage_v**2

    @property
    def hours_running(self) -> float:
        """Hours the load ran (h)."""
        return float(np.sum(self.running * np.diff(self.time_s)) / 3600.0)

    def balance_j(self) -> float:
        """``harvested - (stored change + consumed + leaked + spilled)`` (J): 0 up to rounding."""
        stored = self.stored_j
        return self.harvested_j - (
            float(stored[-1] - stored[0]) + self.consumed_j + self.leaked_j + self.spilled_j
        )


def simulate_storage(
    harvest_w: np.ndarray, *, dt_s: float, load_w: float, storage: StorageConfig
) -> StorageTrace:
    """Step the capacitor through ``harvest_w`` with a load of ``load_w`` when running.

    Args:
        harvest_w: power into the capacitor per step (W, >= 0), shape (N,).
        dt_s: step length (s, > 0).
        load_w: the load's power at its supply rail while running (W, >= 0); the
            capacitor gives ``load_w / storage.converter_efficiency``.
        storage: the capacitor and converter; the trace starts at ``initial_voltage_v``.

    Raises:
        ValueError: negative or non-finite harvest, ``dt_s <= 0`` or ``load_w < 0``.
    """
    harvest = np.asarray(harvest_w, dtype=np.float64)
    if harvest.ndim != 1 or not np.all(np.isfinite(harvest)) or np.any(harvest < 0):
        raise ValueError("harvest_w: need a 1-D array of finite powers >= 0 (W)")
    if not (dt_s > 0 and math.isfinite(dt_s)):
        raise ValueError(f"dt_s = {dt_s!r}: allowed a number > 0 (s)")
    if not (load_w >= 0 and math.isfinite(load_w)):
        raise ValueError(f"load_w = {load_w!r}: allowed a number >= 0 (W)")
    s = storage
    c = s.capacitance_f
    e_max = 0.5 * c * s.max_voltage_v**2
    e_brownout = 0.5 * c * s.brownout_voltage_v**2
    e_restart = 0.5 * c * s.restart_voltage_v**2
    draw = load_w / s.converter_efficiency
    energy = np.empty(len(harvest) + 1)
    running = np.zeros(len(harvest))
    energy[0] = 0.5 * c * s.initial_voltage_v**2
    on = energy[0] >= e_restart
    totals = {"consumed": 0.0, "leaked": 0.0, "spilled": 0.0}
    for i, p_h in enumerate(harvest):
        e = energy[i]
        on = e > e_brownout if on else e >= e_restart
        leak = min(2.0 * e / c / s.leakage_resistance_ohm * dt_s, e)  # V^2 / R dt, E >= 0
        e_next = e + p_h * dt_s - leak
        used = draw * dt_s if on else 0.0
        if on and e_next - used < e_brownout:  # brown-out within the step
            used = max(e_next - e_brownout, 0.0)
            on = False
        e_next -= used
        spill = max(e_next - e_max, 0.0)
        energy[i + 1] = e_next - spill
        running[i] = used / (draw * dt_s) if draw > 0 else float(on)
        totals["consumed"] += used
        totals["leaked"] += leak
        totals["spilled"] += spill
    return StorageTrace(
        time_s=dt_s * np.arange(len(harvest) + 1),
        voltage_v=np.sqrt(2.0 * energy / c),
        running=running,
        harvested_j=float(harvest.sum() * dt_s),
        consumed_j=totals["consumed"],
        leaked_j=totals["leaked"],
        spilled_j=totals["spilled"],
        capacitance_f=c,
    )
