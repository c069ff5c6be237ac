"""Per-pixel statistics of simulated against measured voltages, and their verdicts.

``real = gain * sim + offset`` by least squares with standard errors, correlation,
residual percentiles, the distribution gap (KS statistic and 1-Wasserstein
distance from scipy.stats, raw and after the fit), and for SURROGATE data the
fit against what was injected. Arrays are numpy float64; voltages in volts.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy.stats import ks_2samp, wasserstein_distance

from mincam_render.core.strict_json import JsonObject
from mincam_render.studies.sim2real.result import (
    DistributionGap,
    GainOffsetFit,
    InjectedComparison,
    PixelComparison,
    PixelVerdict,
    Thresholds,
)

#: Verdict thresholds (documented in the report).
THRESHOLDS = Thresholds()
#: Percentiles (%) of the residuals reported per pixel.
RESIDUAL_PERCENTILES = (1, 5, 25, 50, 75, 95, 99)


def fit_gain_offset(sim: np.ndarray, real: np.ndarray) -> GainOffsetFit:
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
        nan = math.nan
        return GainOffsetFit(
            gain=nan,
            offset_v=nan,
            gain_se=nan,
            offset_se_v=nan,
            correlation=nan,
            residual_std_v=nan,
        )
    gain = float(np.sum((x - xm) * (y - ym)) / sxx)
    offset = float(ym - gain * xm)
    resid = y - (gain * x + offset)
    s2 = float(np.sum(resid**2) / (n - 2))
    return GainOffsetFit(
        gain=gain,
        offset_v=offset,
        gain_se=math.sqrt(s2 / sxx),
        offset_se_v=math.sqrt(s2 * (1.0 / n + xm**2 / sxx)),
        correlation=float(np.sum((x - xm) * (y - ym)) / math.sqrt(sxx * syy))
        if syy > 0
        else math.nan,
        residual_std_v=math.sqrt(s2),
    )


def compare_pixels(
    sim_volts: np.ndarray,
    real_volts: np.ndarray,
    detectors: np.ndarray,
    injected: JsonObject | None,
) -> list[PixelComparison]:
    """One comparison per pixel (see :func:`compare_pixel`).

    Args:
        sim_volts: ``V[N, P]`` simulated (V).
        real_volts: ``V[N, P]`` measured (V).
        detectors: ``[P]`` the camera's detector of each pixel.
        injected: a SURROGATE's ``injected.json`` (each pixel is then compared with
            it, :func:`injected_comparison`), or None.
    """
    pixels = [
        compare_pixel(j, int(detectors[j]), sim_volts[:, j], real_volts[:, j])
        for j in range(real_volts.shape[1])
    ]
    if injected is not None:
        pixels = [
            dataclasses.replace(pix, injected=injected_comparison(injected, j, pix.fit))
            for j, pix in enumerate(pixels)
        ]
    return pixels


def compare_pixel(j: int, detector: int, s: np.ndarray, r: np.ndarray) -> PixelComparison:
    """Fit, residual percentiles, distribution gap and verdict of pixel ``j``.

    Args:
        j: the pixel (measurement column).
        detector: the camera's detector it belongs to.
        s: ``[N]`` simulated voltage (V).
        r: ``[N]`` measured voltage (V).
    """
    fit = fit_gain_offset(s, r)
    calibrated = fit.gain * s + fit.offset_v
    resid = r - calibrated
    mean_sim = float(np.mean(s))
    ks_calibrated = float(ks_2samp(calibrated, r, method="asymp").statistic)
    return PixelComparison(
        pixel=j,
        detector=detector,
        fit=fit,
        mean_sim_v=mean_sim,
        mean_real_v=float(np.mean(r)),
        residual_percentiles_v={q: float(np.percentile(resid, q)) for q in RESIDUAL_PERCENTILES},
        ks_raw=float(ks_2samp(s, r, method="asymp").statistic),
        ks_calibrated=ks_calibrated,
        wasserstein_raw_v=float(wasserstein_distance(s, r)),
        wasserstein_calibrated_v=float(wasserstein_distance(calibrated, r)),
        verdict=pixel_verdict(fit, mean_sim, ks_calibrated),
    )


def pixel_verdict(fit: GainOffsetFit, mean_sim_v: float, ks_calibrated: float) -> PixelVerdict:
    """Agrees, agrees after gain/offset calibration, or disagrees (see THRESHOLDS)."""
    th = THRESHOLDS
    shape_ok = fit.correlation >= th.min_correlation
    raw_ok = abs(fit.gain - 1.0) <= th.max_gain_error and abs(
        fit.offset_v
    ) <= th.max_offset_fraction * abs(mean_sim_v)
    if shape_ok and raw_ok:
        return PixelVerdict.AGREES
    if shape_ok and ks_calibrated <= th.max_ks_calibrated:
        return PixelVerdict.AGREES_CALIBRATED
    return PixelVerdict.DISAGREES


def distribution_gap(pixels: list[PixelComparison]) -> DistributionGap:
    """Means over pixels of the KS statistics and 1-Wasserstein distances (V)."""
    return DistributionGap(
        ks_raw_mean=float(np.mean([p.ks_raw for p in pixels])),
        ks_calibrated_mean=float(np.mean([p.ks_calibrated for p in pixels])),
        wasserstein_raw_mean_v=float(np.mean([p.wasserstein_raw_v for p in pixels])),
        wasserstein_calibrated_mean_v=float(np.mean([p.wasserstein_calibrated_v for p in pixels])),
    )


def injected_comparison(injected: JsonObject, j: int, fit: GainOffsetFit) -> InjectedComparison:
    """Pixel ``j``'s fit against what a SURROGATE injected, in standard errors, explained.

    The injected gain and offset are the electronics' own; the expected fit adds
    the stray light and dark current, which a fit of ``real = gain * sim + offset``
    sees as offset. Without geometric or printing perturbations the expected fit is
    exact; with them each pixel's transport changes, so the fit departs from it by
    more than its (OLS, optimistic) standard errors and the sentence says why.

    Args:
        injected: a SURROGATE's ``injected.json`` (``per_pixel`` and ``expected_fit``).
        j: the pixel.
        fit: its fit.
    """
    exp = injected["expected_fit"]
    gain_z = (fit.gain - exp["gain"][j]) / fit.gain_se
    offset_z = (fit.offset_v - exp["offset_v"][j]) / fit.offset_se_v
    far = max(abs(gain_z), abs(offset_z)) > 3.0
    what = (
        f"pixel {j}: fitted gain {fit.gain:.4f} ± {fit.gain_se:.2g} is "
        f"{gain_z:+.1f} se from the expected {exp['gain'][j]:.4f}, offset "
        f"{fit.offset_v * 1e3:.3f} mV is {offset_z:+.1f} se from the expected "
        f"{exp['offset_v'][j] * 1e3:.3f} mV"
    )
    if not far:
        explanation = what + ": within 3 se, as expected."
    elif exp.get("exact"):
        explanation = (
            what + ": more than 3 se although only electronic perturbations were injected; "
            "time-correlated residuals make OLS standard errors optimistic."
        )
    else:
        explanation = (
            what + ": expected to differ, since mask shift/rotation, printing and the board's "
            "pose error change this pixel's transport, so the expected fit is only the "
            "electronics' share (expected_fit.exact = false)."
        )
    return InjectedComparison(
        injected_gain=injected["per_pixel"]["gain"][j],
        injected_offset_v=injected["per_pixel"]["offset_v"][j],
        expected_gain=exp["gain"][j],
        expected_offset_v=exp["offset_v"][j],
        gain_z=gain_z,
        offset_z=offset_z,
        explanation=explanation,
    )
