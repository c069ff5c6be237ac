"""Stability report (issue 7): every stiff or extreme case, its outcome, as a table and JSON.

Usage:
    python benchmarks/bench_stability.py [--out benchmarks/results/stability.json]
        [--quick] [--families patches workspace lighting traffic]

Each case records its parameters and outcome: finite?, saturation where physics
says?, error against a closed form or reference. The float32-vs-float64 cases
show the value a naive float32 computation would have produced next to what the
code does instead. ``--quick`` shrinks sample counts and loop lengths (~1 min);
the full run takes a few minutes on 2 cores. Exit status 1 if any case fails.
"""

from __future__ import annotations

import argparse
import math
import resource
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch
from provenance import machine

from mincam_render import (
    DetectorElectronics,
    DetectorLayout,
    FreeformCamera,
    detector_voltage,
    mask_power,
    parallel_rectangles_coupling,
    render_transport,
)
from mincam_render.core import strict_json
from mincam_render.core.labels import LabelKind, LabelSpec
from mincam_render.core.photometry import lux_to_irradiance
from mincam_render.data.render_job import RenderRequest, plan_render
from mincam_render.learn import train as tr
from mincam_render.optics.camera import MM
from mincam_render.render import backend
from mincam_render.render import mitsuba_scene as ms
from mincam_render.scenes import load_family

ONE = DetectorLayout(positions_m=((0.0, 0.0),))
CASES: list[dict] = []


def case(name: str, params: dict, ok: bool, **outcome) -> None:
    CASES.append({"case": name, "parameters": params, "ok": bool(ok), **outcome})
    print(f"  {'ok  ' if ok else 'FAIL'} {name}", flush=True)


def open_mask_power(cam: FreeformCamera, radiance: float) -> float:
    a, w, d = cam.detector_size_m, cam.mask_size_m, cam.mask_distance_m
    return radiance * parallel_rectangles_coupling(
        (-a / 2, a / 2, -a / 2, a / 2), (-w / 2, w / 2, -w / 2, w / 2), d
    )


def rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * resource.getpagesize() / 2**20


# ---- dynamic range ----------------------------------------------------------------------------


def sun_scene(half_angle_deg: float, lux_sun: float, lux_sky: float):
    delta = math.radians(half_angle_deg)
    l_sun = lux_to_irradiance(lux_sun) / (math.pi * math.sin(delta) ** 2)
    l_sky = lux_to_irradiance(lux_sky) / math.pi
    scene = ms.scene_dict(
        {
            "sun": ms.sphere((0, 0, 100.0), 100 * math.sin(delta), radiance_w_m2_sr=l_sun),
            "sky": ms.constant_environment(l_sky),
        },
        max_depth=1,
    )
    return scene, l_sun, l_sky


def dynamic_range(quick: bool) -> None:
    cam = FreeformCamera(layout=ONE, mask_resolution=(16, 16))
    for lux in (1e-3, 1.0, 1e3, 1e5):
        l_sky = lux_to_irradiance(lux) / math.pi
        t = render_transport(ms.scene_dict({"sky": ms.constant_environment(l_sky)}), cam, spp=64)
        ref = open_mask_power(cam, l_sky)
        err = abs(float(t.sum(dtype=np.float64)) / ref - 1)
        case(
            "uniform sky, lux",
            {"lux": lux, "radiance_w_m2_sr": l_sky},
            bool(np.isfinite(t).all()) and err < 0.01,
            rel_error_vs_closed_form=err,
            power_w=float(t.sum(dtype=np.float64)),
        )

    delta = 5.0
    scene, l_sun, l_sky = sun_scene(delta, 1e5, 1e-3)
    t = render_transport(scene, cam, spp=256 if quick else 2048, seed=0)
    d = math.radians(delta)
    ref = cam.detector_size_m**2 * math.pi * math.sin(d) ** 2 * (l_sun - l_sky)
    ref += open_mask_power(cam, l_sky)
    err = abs(float(t.sum(dtype=np.float64)) / ref - 1)
    case(
        "sun disk (1e5 lux, 5 deg) in a 1e-3 lux sky",
        {"l_sun": l_sun, "l_sky": l_sky},
        bool(np.isfinite(t).all()) and err < 0.1,
        rel_error_vs_closed_form=err,
        max_over_min_texel=float(t.max() / t[t > 0].min()),
    )
    # voltage across gains for the sun through a 0.34-transmittance mask and for moonlight
    p_sun = float(t.sum(dtype=np.float64)) * 0.34
    p_moon = open_mask_power(cam, l_sky) * 0.34
    for gain in (1e4, 1e5, 1e6, 1e7, 1e8, 1e9):
        e = DetectorElectronics(gain_v_per_a=gain)
        p = torch.tensor([[p_moon, p_sun]], dtype=torch.float32, requires_grad=True)
        v = detector_voltage(p, e, noise=True, generator=torch.Generator().manual_seed(0))
        v.sum().backward()
        ideal = e.responsivity_a_per_w * np.array([p_moon, p_sun]) * gain
        sat_expected = ideal > e.full_scale_v
        sat = v.detach().numpy()[0] > e.full_scale_v
        finite = bool(torch.isfinite(v).all() and torch.isfinite(p.grad).all())
        case(
            "gain sweep, moon and sun",
            {"gain_v_per_a": gain},
            finite and bool(np.all(sat == sat_expected) or not sat_expected[0]),
            volts=[float(x) for x in v.detach()[0]],
            saturated=sat.tolist(),
            saturation_expected=sat_expected.tolist(),
            grad_finite=finite,
        )

    scene = ms.scene_dict(
        {
            "faint": ms.rectangle((0.3, 0, 1.0), (0.3, 0, 0), (0.3, 0.6), radiance_w_m2_sr=1e-6),
            "bright": ms.rectangle((-0.3, 0, 1.0), (-0.3, 0, 0), (0.3, 0.6), radiance_w_m2_sr=1e6),
        },
        max_depth=1,
    )
    t = render_transport(scene, cam, spp=16)[0]
    ratio = float(t[:, -6:].sum() / t[:, :6].sum())
    case(
        "emitters 1e-6 and 1e6 W/m2/sr in one scene",
        {"ratio_expected": 1e12},
        bool(np.isfinite(t).all()) and abs(ratio / 1e12 - 1) < 0.05,
        ratio=ratio,
    )


# ---- float32 vs float64 -------------------------------------------------------------------------


def precision() -> None:
    rng = np.random.default_rng(0)
    # (a) accumulating 2^25 per-sample contributions of one texel (spp = 2^25)
    n = 1 << 25
    x = (1e-9 * (1 + 0.5 * rng.standard_normal(n))).astype(np.float32)
    naive = np.cumsum(x, dtype=np.float32)[-1]  # sequential float32 running sum
    exact = float(np.sum(x, dtype=np.float64))
    ours = render_pass_style_sum(x)
    case(
        "float32 running sum of 2^25 samples",
        {"samples": n},
        abs(ours / exact - 1) < 1e-6,
        naive_float32_rel_error=abs(float(naive) / exact - 1),
        ours_rel_error=abs(ours / exact - 1),
        what_the_code_does="per pass (<= 2^23 rays) Dr.Jit block_sum, passes summed in float64 "
        "(transport.render_transport)",
    )

    # (b) P = sum T M over 1024^2 texels: one sun texel and many faint ones
    res = 1024
    t = np.full((1, 1, res, res), 1e-13, np.float32)
    t[0, 0, 0, 0] = 1e-3
    m_logit = torch.zeros(1, res, res)
    exact = float(np.sum(t, dtype=np.float64)) * (0.01 + 0.66 * 0.5)  # of the float32 values
    prod = t.ravel() * np.float32(0.34)
    naive = float(np.cumsum(prod, dtype=np.float32)[-1])
    p32 = float(mask_power(torch.from_numpy(t), m_logit, (0.01, 0.67)))
    p64 = float(mask_power(torch.from_numpy(t).double(), m_logit.double(), (0.01, 0.67)))
    # The bound is a tenth of the float16 storage error the planner allows
    # (RenderRequest.dtype_error_bound = 1e-3), itself a tenth of the 1 % Monte
    # Carlo target: summation must stay well inside what storage already spends.
    bound = 0.1 * RenderRequest.dtype_error_bound
    e32, e_naive = abs(p32 / exact - 1), abs(naive / exact - 1)
    case(
        "sum of 1e6 faint T*M terms after a sun texel",
        {"texels": res * res, "float32_bound": bound},
        abs(p64 / exact - 1) < 1e-9 and e32 < bound and e32 < e_naive,
        naive_float32_rel_error=e_naive,
        mask_power_float32_rel_error=e32,
        mask_power_float64_rel_error=abs(p64 / exact - 1),
        what_the_code_does="torch.bmm accumulates float32 in blocks (not a running sum); pass "
        "float64 transport for float64 accumulation",
    )

    # (c) shot noise at tiny photocurrents (bug fixed: q*I underflowed float32)
    rows = {}
    for current in (1e-29, 1e-27, 1e-25):
        e = DetectorElectronics()
        p = torch.tensor([[current / e.responsivity_a_per_w]], requires_grad=True)
        v = detector_voltage(p, e, noise=True, generator=torch.Generator().manual_seed(0))
        v.sum().backward()
        naive_var = torch.tensor(1.602176634e-19, dtype=torch.float32) * current / (1 / 30)
        rows[f"{current:g}"] = {
            "naive_float32_q_times_I": float(naive_var),
            "grad_finite_now": bool(torch.isfinite(p.grad).all()),
        }
    case(
        "shot-noise sigma at 1e-29..1e-25 A",
        {"currents_a": list(rows)},
        all(r["grad_finite_now"] for r in rows.values()),
        per_current=rows,
        what_the_code_does="sqrt(q/t) in float64 times sqrt(I) (sensor.detector_voltage); "
        "before: sqrt(q*I/t) underflowed to 0 and its gradient was inf",
    )

    # (d) float16 storage of moonlight transport: per-frame power-of-two scales
    from mincam_render.render.precision import decode_transport, encode_transport

    t = (1e-17 * (1 + rng.random((2, 1, 8, 8)))).astype(np.float32)
    naive = t.astype(np.float16).astype(np.float32)
    stored, scales = encode_transport(t, "float16")
    back = decode_transport(stored, scales)
    err = float(np.max(np.abs(back / t - 1)))
    case(
        "float16 storage of 1e-17 W texels",
        {"dtype": "float16"},
        err < 1e-3,
        naive_float16_max_rel_error=float(np.max(np.abs(naive / t - 1))),
        scaled_max_rel_error=err,
        what_the_code_does="stored = T / 2^ceil(log2 max T) per frame (render.precision.encode_transport)",
    )


def render_pass_style_sum(x: np.ndarray, rays_per_pass: int = 1 << 23) -> float:
    """Per-pass float32 tree sum (like Dr.Jit's block_sum), passes added in float64."""
    total = 0.0
    for i in range(0, len(x), rays_per_pass):
        total += float(np.sum(x[i : i + rays_per_pass], dtype=np.float32))  # pairwise
    return total


# ---- stiff optimisation -------------------------------------------------------------------------

COUNT = LabelSpec(name="count", kind=LabelKind.COUNT, median_filter_s=0.0)


def linear_task(n=260, res=8, scale=2e-8, electronics=None):
    rng = np.random.default_rng(0)
    cam = FreeformCamera(
        mask_resolution=(res, res),
        layout=DetectorLayout.row(count=2, pitch_m=20 * MM),
        electronics=electronics or DetectorElectronics(),
    )
    base = rng.uniform(0.0, 1.0, (n, 1, res, res)).astype(np.float32)
    t = np.repeat(base, 2, axis=1) * np.float32(scale)
    sig = base[:, 0, : res // 2].mean(axis=(1, 2)) - base[:, 0, res // 2 :].mean(axis=(1, 2))
    count = np.clip(np.rint(5 + 40 * sig), 0, None).astype(np.float32)[:, None]
    return tr.TrainingData(
        transport=t, labels={"count": count}, label_specs=(COUNT,), camera=cam, fps=30.0
    ).split((0.7, 0.15, 0.15))


def _finite(model) -> bool:
    return all(
        torch.isfinite(v).all() for v in model.state_dict().values() if v.is_floating_point()
    )


def stiff(quick: bool) -> None:
    steps = 300  # recovery from a pinned start needs ~300 steps of this toy task
    cfg = tr.TrainConfig(max_steps=steps, batch_size=32, eval_every=50, patience=100)
    for logit in (-1e4, -50.0, 0.0, 50.0, 1e4):
        lg = torch.full((1, 4, 4), logit, requires_grad=True)
        p = mask_power(torch.full((1, 1, 4, 4), 1e-6), lg, (0.01, 0.67))
        p.sum().backward()
        train, val, _ = linear_task()
        model = tr.build_mincam(train, 2)
        with torch.no_grad():
            model.logits.fill_(logit)
        before = tr.predict(model, val)[2]
        tr.train_model(model, train, val, cfg)
        after = tr.predict(model, val)[2]
        ok = (
            _finite(model)
            and bool(torch.isfinite(lg.grad).all())
            and (logit == 0 or after < 0.6 * before)
        )
        case(
            "masks start at logit",
            {"logit": logit, "steps": steps},
            ok,
            mask_grad_finite=bool(torch.isfinite(lg.grad).all()),
            val_loss_before=before,
            val_loss_after=after,
            logit_std_after=float(model.logits.detach().std()),
        )
    for slope in (1e-6, 1e-3, 1.0):
        train, val, _ = linear_task(
            scale=2e-3, electronics=DetectorElectronics(saturation_slope=slope)
        )
        model = tr.build_mincam(train, 2)
        before = tr.predict(model, val)[2]
        tr.train_model(model, train, val, cfg)
        after = tr.predict(model, val)[2]
        case(
            "saturated detectors (1e5 x full scale), leaky slope",
            {"slope": slope},
            _finite(model) and after < before,
            val_loss_before=before,
            val_loss_after=after,
        )
    train, val, _ = linear_task(scale=1e-16)
    model = tr.build_mincam(train, 2)
    res = tr.train_model(model, train, val, cfg)
    case(
        "noise dominates signal (1e-3 of read noise)",
        {"scale_w": 1e-16},
        _finite(model) and all(math.isfinite(h["val_loss"]) for h in res.history),
        val_loss=res.best_val_loss,
    )
    for lr, mask_lr in ((0.9, 9.9), (0.3, 5.0), (1e-3, 0.05)):
        train, val, _ = linear_task()
        model = tr.build_mincam(train, 2)
        res = tr.train_model(model, train, val, replace(cfg, lr=lr, mask_lr=mask_lr))
        case(
            "learning rates near divergence",
            {"lr": lr, "mask_lr": mask_lr},
            _finite(model) and math.isfinite(res.best_val_loss),
            best_val_loss=res.best_val_loss,
        )


# ---- geometry -----------------------------------------------------------------------------------


def geometry() -> None:
    cam = FreeformCamera(layout=ONE, mask_resolution=(16, 16))
    for gap in (1e-3, 1e-5):
        z = cam.mask_distance_m + gap
        wall = ms.rectangle((0, 0, z), (0, 0, -1.0), (0.5, 0.5), radiance_w_m2_sr=3.0)
        t = render_transport(ms.scene_dict({"wall": wall}, max_depth=1), cam, spp=64)
        err = abs(float(t.sum(dtype=np.float64)) / open_mask_power(cam, 3.0) - 1)
        case(
            "emitting wall touching the mask plane",
            {"gap_m": gap},
            bool(np.isfinite(t).all()) and err < 0.01,
            rel_error_vs_closed_form=err,
        )
    d = cam.mask_distance_m
    board = ms.rectangle((0, 0, d), (1.0, 0, d), (0.02, 2.0), ms.diffuse(0.5))
    t = render_transport(
        ms.scene_dict({"board": board, "sky": ms.constant_environment(1.0)}, max_depth=3),
        cam,
        spp=64,
    )
    case(
        "board cutting through the mask plane",
        {},
        bool(np.isfinite(t).all() and (t >= 0).all()),
        power_w=float(t.sum()),
    )
    t = render_transport({"type": "scene"}, cam, spp=4)
    case("empty scene", {}, bool(np.all(t == 0)), power_w=float(t.sum()))


# ---- temporal extremes, lights off -------------------------------------------------------------


def temporal(families: list[str]) -> None:
    for name in families:
        for fps in (1.0, 1000.0):
            try:
                fam = load_family(name, seed=0, num_frames=12, overrides={"fps": fps})
                lab = [fam.frame_labels(i) for i in (0, 11)] if hasattr(fam, "frame_labels") else []
                ok = fam.fps == fps and all(np.isfinite(v).all() for d in lab for v in d.values())
                case("family frame rate", {"family": name, "fps": fps}, ok)
            except ImportError as err:
                case("family frame rate", {"family": name, "fps": fps}, True, skipped=str(err))
    from mincam_render.scenes.traffic import TrafficConfig, traffic_labels

    cam = TrafficConfig().camera.camera()
    pos, fwd, right = np.asarray(cam.position), cam.frame[2], cam.frame[0]
    centre = pos + (0.7 - pos[2]) / fwd[2] * fwd
    for kmh, mph in ((0.0, 0.0), (200.0, 124.27)):
        lab = traffic_labels(cam, centre[None], [math.atan2(-right[1], -right[0])], [kmh / 3.6])
        got = float(lab["speed_left_mph"][0])
        case("vehicle speed label", {"km_h": kmh}, abs(got - mph) < 0.01, mph=got)
    fam = load_family("lighting", seed=0, num_frames=2)
    scene = fam.build_scene()
    cam = replace(fam.config.camera, detectors=2, mask_resolution=8).camera()
    from mincam_render.scenes.indoor import IndoorState

    n = len(fam.labels[0].element_names)
    fam.apply_state(scene, IndoorState(lights_on=(False,) * n))
    t = render_transport(scene, cam, spp=8)
    case(
        "lighting, all lights off",
        {},
        bool(np.isfinite(t).all()) and float(t.sum()) == 0.0,
        power_w=float(t.sum()),
    )


# ---- variance at the auto fidelity ---------------------------------------------------------------


def variance(families: list[str], quick: bool) -> None:
    from mincam_render.core.seeds import frame_seed

    seeds = 4 if quick else 8
    for name in families:
        over = {"camera": {"detectors": 2, "mask_resolution": 16}}
        try:
            m = plan_render(
                RenderRequest(family=name, num_frames=64, overrides=over, target_error=0.01)
            )
        except ImportError as err:
            case("measurement variance at auto spp", {"family": name}, True, skipped=str(err))
            continue
        spp = m["fidelity"]["spp"]["value"]
        depth = m["job"]["render"]["max_depth"] or None
        fam = load_family(name, seed=0, num_frames=64, overrides=over)
        scene = fam.build_scene()
        cam = fam.camera()
        rng = np.random.default_rng(0)
        lo, hi = cam.transmittance_range
        masks = rng.uniform(lo, hi, (16, *cam.mask_resolution))
        rel = []
        for frame in (0, 32):
            fam.set_frame(scene, frame)
            ts = np.stack(
                [
                    render_transport(
                        scene, cam, spp=spp, max_depth=depth, seed=frame_seed(s, frame)
                    )
                    for s in range(seeds)
                ]
            )
            p = np.einsum("skrc,mrc->skm", ts.astype(np.float64), masks)
            mean = p.mean(axis=0)
            ok_ = mean > 0
            rel.append(p.std(axis=0, ddof=1)[ok_] / mean[ok_])
        rel = np.concatenate(rel)
        case(
            "measurement variance at auto spp",
            {"family": name, "spp": spp, "seeds": seeds},
            bool(np.all(np.isfinite(rel))) and float(rel.max()) < 0.1,
            rel_std_median=float(np.median(rel)),
            rel_std_max=float(rel.max()),
            target_error=0.01,
        )
    # a real-size sun disk (0.27 deg): few samples hit it -> fireflies
    cam = FreeformCamera(layout=ONE, mask_resolution=(16, 16))
    scene, _, _ = sun_scene(0.267, 1e5, 1e-3)
    p = [
        float(render_transport(scene, cam, spp=256, seed=s).sum(dtype=np.float64))
        for s in range(seeds)
    ]
    case(
        "real sun disk (0.27 deg), 256 spp, open mask",
        {"seeds": seeds},
        True,
        rel_std=float(np.std(p, ddof=1) / np.mean(p)),
        note="uniform mask sampling hits a 0.27-deg disk with p ~ 3e-5 per ray; the sky "
        "modules use a directional sun (delta light) instead, which camera rays never hit",
    )


# ---- memory over long runs -----------------------------------------------------------------------


def memory(quick: bool) -> None:
    frames = 100 if quick else 400
    fam = load_family("workspace", seed=0, num_frames=frames)
    scene = fam.build_scene()
    cam = replace(fam.config.camera, detectors=2, mask_resolution=16).camera()
    rss = []
    for i in range(frames):
        fam.set_frame(scene, i)
        render_transport(scene, cam, spp=4, seed=i)
        if i % 10 == 0:
            rss.append(rss_mb())
    growth = rss[-1] - rss[min(3, len(rss) - 1)]
    case(
        "RSS over a long render",
        {"frames": frames, "family": "workspace"},
        growth < 60,
        rss_mb_samples=[round(r, 1) for r in rss],
        growth_after_warmup_mb=growth,
    )
    train, val, _ = linear_task(400)
    model = tr.build_mincam(train, 2)
    cfg = tr.TrainConfig(max_steps=200, batch_size=32, eval_every=100, patience=100)
    rss = []
    for _ in range(5 if quick else 15):
        tr.train_model(model, train, val, cfg)
        rss.append(rss_mb())
    growth = rss[-1] - rss[min(2, len(rss) - 1)]
    case(
        "RSS over a long training",
        {"steps": 200 * len(rss)},
        growth < 40,
        rss_mb_samples=[round(r, 1) for r in rss],
        growth_after_warmup_mb=growth,
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/stability.json"))
    ap.add_argument("--quick", action="store_true")
    ap.add_argument(
        "--families", nargs="+", default=["patches", "workspace", "lighting", "traffic"]
    )
    args = ap.parse_args()
    backend.use_variant()
    t0 = time.perf_counter()
    for section in (
        "dynamic_range",
        "precision",
        "stiff",
        "geometry",
        "temporal",
        "variance",
        "memory",
    ):
        print(f"[{section}]", flush=True)
        fn = globals()[section]
        kw = {}
        if "quick" in fn.__code__.co_varnames[: fn.__code__.co_argcount]:
            kw["quick"] = args.quick
        if "families" in fn.__code__.co_varnames[: fn.__code__.co_argcount]:
            kw["families"] = args.families
        fn(**kw)
    print()
    print(f"{'ok':4} {'case':52} {'parameters':40} outcome")
    for c in CASES:
        outcome = {
            k: v
            for k, v in c.items()
            if k not in ("case", "parameters", "ok")
            and not isinstance(v, list | dict)
            and k not in ("what_the_code_does", "note")
        }
        short = ", ".join(
            f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}" for k, v in outcome.items()
        )
        params = ", ".join(
            f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in c["parameters"].items()
        )
        print(f"{'ok' if c['ok'] else 'FAIL':4} {c['case'][:52]:52} {params[:40]:40} {short}")
    result = {
        "benchmark": "stability",
        "machine": machine(),
        "variant": backend.describe()["variant"],
        "quick": args.quick,
        "seconds": time.perf_counter() - t0,
        "cases": CASES,
        "failed": [c["case"] for c in CASES if not c["ok"]],
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(strict_json.dumps(result, indent=1) + "\n")
    print(f"\n{len(CASES) - len(result['failed'])}/{len(CASES)} cases ok; wrote {args.out}")
    return 1 if result["failed"] else 0


if __name__ == "__main__":
    raise SystemExit(main())
