"""Per-pixel statistics of simulated against measured voltages, and their verdicts.

``real = gain * sim + offset`` by least squares with standard errors, correlation,
residual percentiles, the distribution gap (KS statistic and 1-Wasserstein
distance from scipy.stats, raw and after the fit), and for SURROGATE data the
fit against what was injected. Arrays are numpy float64; voltages in volts.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.stats import ks_2samp, wasserstein_distance

#: Verdict thresholds (documented in the report).
THRESHOLDS = {
    "min_correlation": 0.9,  # simulated and measured time series move together
    "max_gain_error": 0.1,  # |gain - 1| for 'agrees without calibration'
    "max_offset_fraction": 0.05,  # |offset| / mean simulated voltage, same
    "max_ks_calibrated": 0.2,  # KS statistic after the per-pixel gain/offset fit
    "max_task_gap": 0.2,  # task error may exceed the real-trained one by 20 %
}
#: Percentiles (%) of the residuals reported per pixel.
RESIDUAL_PERCENTILES = (1, 5, 25, 50, 75, 95, 99)


def fit_gain_offset(sim: np.ndarray, real: np.ndarray) -> dict[str, float]:
    """Least-squares ``real = gain * sim + offset`` with standard errors and correlation.

    Standard errors assume independent residuals (OLS); time-correlated residuals
    make them optimistic.
    """
    x = np.asarray(sim, np.float64)
    y = np.asarray(real, np.float64)
    n = len(x)
    xm, ym = x.mean(), y.mean()
    sxx = float(np.sum((x - xm) ** 2))
    syy = float(np.sum((y - ym) ** 2))
    if sxx <= 0 or n < 3:
        return {
            "gain": math.nan,
            "offset_v": math.nan,
            "gain_se": math.nan,
            "offset_se_v": math.nan,
            "correlation": math.nan,
            "residual_std_v": math.nan,
        }
    gain = float(np.sum((x - xm) * (y - ym)) / sxx)
    offset = float(ym - gain * xm)
    resid = y - (gain * x + offset)
    s2 = float(np.sum(resid**2) / (n - 2))
    return {
        "gain": gain,
        "offset_v": offset,
        "gain_se": math.sqrt(s2 / sxx),
        "offset_se_v": math.sqrt(s2 * (1.0 / n + xm**2 / sxx)),
        "correlation": float(np.sum((x - xm) * (y - ym)) / math.sqrt(sxx * syy))
        if syy > 0
        else math.nan,
        "residual_std_v": math.sqrt(s2),
    }


def compare_pixels(
    sim_volts: np.ndarray, real_volts: np.ndarray, detectors: np.ndarray, injected: dict | None
) -> list[dict[str, Any]]:
    """One JSON-ready comparison per pixel (see :func:`compare_pixel`).

    Args:
        sim_volts: ``V[N, P]`` simulated (V).
        real_volts: ``V[N, P]`` measured (V).
        detectors: ``[P]`` the camera's detector of each pixel.
        injected: a SURROGATE's injected values (each pixel is then compared with
            them, :func:`injected_comparison`), or None.
    """
    pixels = [
        compare_pixel(j, int(detectors[j]), sim_volts[:, j], real_volts[:, j])
        for j in range(real_volts.shape[1])
    ]
    if injected is not None:
        for j, pix in enumerate(pixels):
            pix.update(injected_comparison(injected, j, pix))
    return pixels


def compare_pixel(j: int, detector: int, s: np.ndarray, r: np.ndarray) -> dict[str, Any]:
    """Fit, residual percentiles, distribution gap and verdict of pixel ``j``.

    Args:
        j: the pixel (measurement column).
        detector: the camera's detector it belongs to.
        s: ``[N]`` simulated voltage (V).
        r: ``[N]`` measured voltage (V).
    """
    fit = fit_gain_offset(s, r)
    calibrated = fit["gain"] * s + fit["offset_v"]
    resid = r - calibrated
    mean_sim = float(np.mean(s))
    pix: dict[str, Any] = {
        "pixel": j,
        "detector": detector,
        **fit,
        "mean_sim_v": mean_sim,
        "mean_real_v": float(np.mean(r)),
        "residual_percentiles_v": {
            str(q): float(np.percentile(resid, q)) for q in RESIDUAL_PERCENTILES
        },
        "ks_raw": float(ks_2samp(s, r, method="asymp").statistic),
        "ks_calibrated": float(ks_2samp(calibrated, r, method="asymp").statistic),
        "wasserstein_raw_v": float(wasserstein_distance(s, r)),
        "wasserstein_calibrated_v": float(wasserstein_distance(calibrated, r)),
    }
    pix["verdict"] = pixel_verdict(fit, mean_sim, pix["ks_calibrated"])
    return pix


def pixel_verdict(fit: dict[str, float], mean_sim_v: float, ks_calibrated: float) -> str:
    """'agrees', 'agrees after gain/offset calibration' or 'disagrees' (see THRESHOLDS)."""
    th = THRESHOLDS
    shape_ok = fit["correlation"] >= th["min_correlation"]
    raw_ok = abs(fit["gain"] - 1.0) <= th["max_gain_error"] and abs(fit["offset_v"]) <= th[
        "max_offset_fraction"
    ] * abs(mean_sim_v)
    if shape_ok and raw_ok:
        return "agrees"
    if shape_ok and ks_calibrated <= th["max_ks_calibrated"]:
        return "agrees after gain/offset calibration"
    return "disagrees"


def distribution_gap(pixels: list[dict[str, Any]]) -> dict[str, float]:
    """Means over pixels of the KS statistics and 1-Wasserstein distances (V)."""
    return {
        "ks_raw_mean": float(np.mean([p["ks_raw"] for p in pixels])),
        "ks_calibrated_mean": float(np.mean([p["ks_calibrated"] for p in pixels])),
        "wasserstein_raw_mean_v": float(np.mean([p["wasserstein_raw_v"] for p in pixels])),
        "wasserstein_calibrated_mean_v": float(
            np.mean([p["wasserstein_calibrated_v"] for p in pixels])
        ),
    }


def injected_comparison(injected: dict, j: int, fit: dict) -> dict[str, Any]:
    """Pixel ``j``'s fit against what a SURROGATE injected, in standard errors, explained.

    The injected gain and offset are the electronics' own; the expected fit adds
    the stray light and dark current, which a fit of ``real = gain * sim + offset``
    sees as offset. Without geometric or printing perturbations the expected fit is
    exact; with them each pixel's transport changes, so the fit departs from it by
    more than its (OLS, optimistic) standard errors and the sentence says why.
    """
    exp = injected["expected_fit"]
    out = {
        "injected_gain": injected["per_pixel"]["gain"][j],
        "injected_offset_v": injected["per_pixel"]["offset_v"][j],
        "expected_gain": exp["gain"][j],
        "expected_offset_v": exp["offset_v"][j],
        "gain_z": (fit["gain"] - exp["gain"][j]) / fit["gain_se"],
        "offset_z": (fit["offset_v"] - exp["offset_v"][j]) / fit["offset_se_v"],
    }
    far = max(abs(out["gain_z"]), abs(out["offset_z"])) > 3.0
    what = (
        f"pixel {j}: fitted gain {fit['gain']:.4f} ± {fit['gain_se']:.2g} is "
        f"{out['gain_z']:+.1f} se from the expected {exp['gain'][j]:.4f}, offset "
        f"{fit['offset_v'] * 1e3:.3f} mV is {out['offset_z']:+.1f} se from the expected "
        f"{exp['offset_v'][j] * 1e3:.3f} mV"
    )
    if not far:
        out["explanation"] = what + ": within 3 se, as expected."
    elif exp.get("exact"):
        out["explanation"] = (
            what + ": more than 3 se although only electronic perturbations were injected; "
            "time-correlated residuals make OLS standard errors optimistic."
        )
    else:
        out["explanation"] = (
            what + ": expected to differ, since mask shift/rotation, printing and the board's "
            "pose error change this pixel's transport, so the expected fit is only the "
            "electronics' share (expected_fit.exact = false)."
        )
    return out
