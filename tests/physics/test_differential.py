"""Differential rendering: background keys, exact cancellation, unbiasedness, datasets."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from support import TINY_DIFFERENTIAL

from mincam_render.data import dataset as ds
from mincam_render.render import precision
from mincam_render.render.capabilities import DifferentialBackground
from mincam_render.render.differential import (
    Background,
    BackgroundSettings,
    DifferenceSeeds,
    background_family,
    background_seed,
    render_background,
    render_frame,
)
from mincam_render.render.transport import render_transport
from mincam_render.scenes import load_family

#: nobody ever comes and the door stays shut: every frame equals its background
EMPTY_ROOM = {"arrivals_per_min": 0.0, "burn_in_s": 0.0, "door": {"mean_propped_s": 0.0}}


def _small(camera):
    return dataclasses.replace(camera, mask_resolution=(8, 8))


def test_background_keys_follow_daylight_windows_and_lights(variant):
    """Two frames share a background iff same lights and same daylight window."""
    fam = load_family("workspace", seed=0, num_frames=600, overrides={"fps": 2.0})
    interval = 30.0
    keys = [fam.background_key(i, interval) for i in range(fam.num_frames)]
    window = np.floor(np.arange(fam.num_frames) / fam.fps / interval)
    lights = [tuple(row) for row in fam.lights_on]
    rng = np.random.default_rng(0)
    pairs = rng.integers(0, fam.num_frames, size=(2000, 2))
    pairs = np.concatenate([pairs, np.stack([np.arange(599), np.arange(1, 600)], axis=1)])
    same_key = np.array([keys[i] == keys[j] for i, j in pairs])
    same_state = np.array([window[i] == window[j] and lights[i] == lights[j] for i, j in pairs])
    np.testing.assert_array_equal(same_key, same_state)
    assert same_key.any() and not same_key.all()
    assert len({lt for lt in lights}) > 1  # the lights do switch in this sequence


def test_families_without_background_say_so(variant):
    fam = load_family("patches", seed=0, num_frames=4)
    assert not isinstance(fam, DifferentialBackground)
    with pytest.raises(ValueError, match="'patches' has no static background"):
        background_family(fam)


def test_background_seed_is_a_pure_function_of_seed_and_key():
    assert background_seed(3, "a") == background_seed(3, "a")
    assert len({background_seed(3, "a"), background_seed(4, "a"), background_seed(3, "b")}) == 3
    assert 0 <= background_seed(2**62, "x") < 2**63


def test_frames_without_movers_cancel_exactly(variant):
    """Common random numbers: X and C are the same paths, so the estimate is the
    interpolated background bit for bit, also late in a window whose daylight drifts."""
    fam = load_family("workspace", seed=0, num_frames=60, overrides={**EMPTY_ROOM, "fps": 1.0})
    index = 40
    assert fam.track.active[index].sum() == 0 and fam.track.door_angle_rad[index] == 0.0
    scene, cam = fam.build_scene(), _small(fam.camera())
    settings = BackgroundSettings(interval_s=60.0, spp=16, max_depth=6)
    bg = render_background(fam, scene, cam, index, settings, dataset_seed=1, spp=4, max_depth=3)
    weights = fam.background_components(index, 60.0)
    assert weights["daylight_s=0"] == pytest.approx(20 / 60)
    assert weights["daylight_s=60"] == pytest.approx(40 / 60)
    t, _ = render_frame(fam, scene, cam, index, bg, spp=4, max_depth=3)
    np.testing.assert_array_equal(t, bg.converged(weights).astype(np.float32))
    # the daylight does drift within the window (so X uses the window's start, not t)
    start, end = bg.components["daylight_s=0"], bg.components["daylight_s=60"]
    assert np.abs(end - start).sum() > 0.01 * np.abs(start).sum()


def test_components_follow_the_lights_and_the_window(variant):
    """Lights on weigh 1, the daylight at the window's ends 1 - a and a (a on the
    daylight's update grid); bad component keys are refused."""
    fam = load_family(
        "workspace", seed=0, num_frames=200, overrides={"fps": 4.0, "daylight_update_s": 2.0}
    )
    lights = [li.key for li in fam.rig.lights]
    for index, a in ((0, 0.0), (40, 0.0), (47, 0.0), (48, 0.2), (79, 0.8)):
        # t = index / 4 s; windows of 10 s; daylight shown every 2 s
        on = [k for k, v in zip(lights, fam.state(index).lights_on, strict=True) if v]
        t0 = 10 * (index // 40)
        expected = {f"light={k}": 1.0 for k in on}
        expected[f"daylight_s={t0}"] = 1.0 - a
        expected[f"daylight_s={t0 + 10}"] = a
        got = fam.background_components(index, 10.0)
        assert got.keys() == expected.keys()
        for k, w in expected.items():
            assert got[k] == pytest.approx(w)
    with pytest.raises(ValueError, match="interval_s"):
        fam.background_components(3, 0.0)
    with pytest.raises(ValueError, match="at = "):
        fam.set_background(fam.build_scene(), 3, 10.0, at=1.5)
    with pytest.raises(ValueError, match="not a background component"):
        fam.set_background_component(fam.build_scene(), "light=nosuchlamp")


def test_components_sum_to_the_background(variant):
    """Linearity: daylight with the lights off plus each light alone is the background
    with its lights on (statistically, 3 sigma of independent renders)."""
    fam = load_family("workspace", seed=0, num_frames=4)
    scene, cam = fam.build_scene(), _small(fam.camera())
    lo_hi = cam.transmittance_range
    state = fam.state(0)
    keys = [f"light={li.key}" for li in fam.rig.lights] + ["daylight_s=0"]
    total = 0.0
    for i, key in enumerate(keys):
        fam.set_background_component(scene, key)
        total = total + render_transport(scene, cam, spp=512, seed=10 + i, max_depth=6)
    from mincam_render.scenes.indoor import IndoorState

    all_on = (True,) * len(fam.rig.lights)
    fam.rig.apply(scene, IndoorState(lights_on=all_on, daylight_time_s=state.daylight_time_s))
    full = [render_transport(scene, cam, spp=512, seed=s, max_depth=6) for s in (1, 2)]
    err = precision.measurement_relative_error(total[None], full[0][None], lo_hi)["rms"]
    noise = precision.measurement_relative_error(full[1][None], full[0][None], lo_hi)["rms"]
    assert err < 3 * noise
    # and each part matters: the daylight alone is far from the whole
    fam.set_background_component(scene, "daylight_s=0")
    day = render_transport(scene, cam, spp=512, seed=3, max_depth=6)
    assert precision.measurement_relative_error(day[None], full[0][None], lo_hi)["rms"] > 10 * noise


def test_components_are_shared_between_backgrounds(variant):
    """A window's end is the next one's start: rendered once, and identical when
    rendered anew (its seed depends on its key only)."""
    fam = load_family("workspace", seed=0, num_frames=120, overrides={"fps": 1.0})
    scene, cam = fam.build_scene(), _small(fam.camera())
    settings = BackgroundSettings(interval_s=30.0, spp=4, max_depth=3)
    first, second = 0, 30
    assert fam.state(first).lights_on == fam.state(second).lights_on
    lights_on = sum(fam.state(first).lights_on)
    cache: dict = {}
    kw = {"dataset_seed": 5, "spp": 2, "max_depth": 3}
    a = render_background(fam, scene, cam, first, settings, component_cache=cache, **kw)
    assert len(cache) == 2 + lights_on
    b = render_background(fam, scene, cam, second, settings, component_cache=cache, **kw)
    assert len(cache) == 3 + lights_on  # only the second window's end is new
    assert b.components["daylight_s=30"] is a.components["daylight_s=30"]
    fresh = render_background(fam, scene, cam, second, settings, **kw)
    for key, array in fresh.components.items():
        np.testing.assert_array_equal(array, b.components[key])
    np.testing.assert_array_equal(fresh.same_seed_w, b.same_seed_w)


def test_interpolated_background_tracks_the_drifting_daylight(variant):
    """Halfway through a window, (B_0 + B_1) / 2 matches the background rendered at
    that time far better than B_0 does."""
    fam = load_family("workspace", seed=0, num_frames=4)
    scene, cam = fam.build_scene(), _small(fam.camera())
    lo_hi = cam.transmittance_range
    renders = []
    for at in (0.0, 0.5, 1.0):
        fam.set_background(scene, 0, 60.0, at=at)
        renders.append(render_transport(scene, cam, spp=256, seed=3, max_depth=6)[None])
    start, middle, end = renders
    interpolated = precision.measurement_relative_error(0.5 * (start + end), middle, lo_hi)["rms"]
    held = precision.measurement_relative_error(start, middle, lo_hi)["rms"]
    assert held > 0.01  # 30 s of the time-lapsed day moves the light by per cents
    assert interpolated < 0.1 * held


@pytest.mark.parametrize("shared", [False, True])
def test_frame_is_background_plus_difference_per_detector_or_shared(variant, shared):
    """T_k = B_k + X - C, with X and C from the board centre for every k when shared."""
    fam = load_family("workspace", seed=0, num_frames=600)
    index = int(np.flatnonzero(fam.track.active.sum(axis=1) >= 2)[0])
    scene, cam = fam.build_scene(), _small(fam.camera())
    settings = BackgroundSettings(interval_s=60.0, spp=8, max_depth=3, shared_difference=shared)
    bg = render_background(fam, scene, cam, index, settings, dataset_seed=0, spp=2, max_depth=3)
    t, _ = render_frame(fam, scene, cam, index, bg, spp=2, max_depth=3)
    diff_cam = cam.rendered_camera(shared)
    assert all(c.shape == (cam.num_detectors, 8, 8) for c in bg.components.values())
    assert bg.same_seed_w.shape == (diff_cam.num_detectors, 8, 8)
    fam.set_frame_in_window(scene, index, settings.interval_s)
    x = fam.render_transport(scene, diff_cam, spp=2, seed=bg.seed, max_depth=3)
    weights = fam.background_components(index, settings.interval_s)
    expected = sum(w * bg.components[k].astype(np.float64) for k, w in weights.items())
    expected += x - bg.same_seed_w
    # float32 rounding of sums taken in another order
    atol = 1e-6 * np.abs(expected).max()
    np.testing.assert_allclose(t, expected.astype(np.float32), rtol=1e-6, atol=atol)
    assert t.shape == (cam.num_detectors, 8, 8)
    assert np.any(x != bg.same_seed_w)  # the people do change the light


def test_render_frame_refuses_another_frames_background(variant):
    fam = load_family("workspace", seed=0, num_frames=200, overrides={"fps": 2.0})
    scene, cam = fam.build_scene(), _small(fam.camera())
    settings = BackgroundSettings(interval_s=30.0, spp=1, max_depth=2)
    bg = render_background(fam, scene, cam, 0, settings, dataset_seed=0, spp=1, max_depth=2)
    with pytest.raises(ValueError, match="has background"):
        render_frame(fam, scene, cam, 100, bg, spp=1, max_depth=2)


def test_estimate_is_unbiased_and_less_noisy_than_plain(variant):
    """Mean of B + X - C over seeds matches a plain reference; its noise is lower at equal spp."""
    fam = load_family("workspace", seed=0, num_frames=600)
    index = int(np.flatnonzero(fam.track.active.sum(axis=1) >= 2)[0])
    scene, cam = fam.build_scene(), _small(fam.camera())
    lo_hi = cam.transmittance_range
    depth, spp, big = 8, 16, 4096
    settings = BackgroundSettings(interval_s=60.0, spp=big, max_depth=depth)
    bg0 = render_background(
        fam, scene, cam, index, settings, dataset_seed=0, spp=spp, max_depth=depth
    )
    diffs, plains = [], []
    for s in range(6):
        # a fresh seed s for X and C, the same converged B
        seed = background_seed(s, bg0.key)
        fam.set_background(scene, index, settings.interval_s)
        same = fam.render_transport(scene, cam, spp=spp, seed=seed, max_depth=depth)
        bg = dataclasses.replace(bg0, seed=seed, same_seed_w=same)
        diffs.append(render_frame(fam, scene, cam, index, bg, spp=spp, max_depth=depth)[0])
        fam.set_frame(scene, index)
        plains.append(fam.render_transport(scene, cam, spp=spp, seed=100 + s, max_depth=depth))
    ref = fam.render_transport(scene, cam, spp=big, seed=999, max_depth=depth)
    diffs, plains = np.stack(diffs), np.stack(plains)
    # one estimate's relative noise (the difference of two has sqrt(2) times more)
    noise_diff = precision.measurement_relative_error(diffs[:3], diffs[3:], lo_hi)["rms"] / np.sqrt(
        2
    )
    noise_plain = precision.measurement_relative_error(plains[:3], plains[3:], lo_hi)[
        "rms"
    ] / np.sqrt(2)
    assert noise_diff < 0.6 * noise_plain
    # the mean of 6 estimates shares one B; B and the reference each carry the
    # plain noise at 4096 spp: 3 sigma of that combination
    err = precision.measurement_relative_error(diffs.mean(0)[None], ref[None], lo_hi)["rms"]
    sigma = np.sqrt(noise_diff**2 / 6 + 2 * noise_plain**2 * spp / big)
    assert err < 3 * sigma


def test_differential_dataset_records_backgrounds(differential_dataset):
    import json

    request, out = TINY_DIFFERENTIAL, differential_dataset
    manifest = ds.read_manifest(out)
    job = manifest["job"]
    assert job["render"]["background"] == {
        "interval_s": 10.0,
        "spp": 8,
        "max_depth": 3,
        "shared_difference": True,
        "difference_seeds": "window",
    }
    fam = load_family("workspace", seed=0, num_frames=24, overrides=request.overrides)
    keys = [fam.background_key(i, 10.0) for i in range(24)]
    assert job["backgrounds"] == list(dict.fromkeys(keys))  # first-seen order
    assert len(job["backgrounds"]) >= 3  # 24 s at 1 fps in 10 s windows, plus light switches
    seeds = {}
    for rec in manifest["backgrounds"]:
        assert ds.sha256_file(out / rec["file"]) == rec["sha256"]
        # C (and every X) once from the board centre
        assert np.load(out / rec["file"]).shape == (1, 8, 8)
        assert rec["components"] == job["background_parts"][rec["key"]]
        seeds[rec["key"]] = rec["seed"]
    # components per detector, each rendered once, all of them used
    assert len(manifest["background_components"]) == len(job["background_components"])
    for rec in manifest["background_components"]:
        assert ds.sha256_file(out / rec["file"]) == rec["sha256"]
        assert np.load(out / rec["file"]).shape == (2, 8, 8)
    used = {c for parts in job["background_parts"].values() for c in parts}
    assert used == set(job["background_components"])
    # 24 s at 1 fps in 10 s windows: the daylight at 0, 10, 20, 30 s plus lights
    assert {c for c in used if c.startswith("daylight")} == {
        f"daylight_s={t}" for t in (0, 10, 20, 30)
    }
    for shard in manifest["shards"]:
        for frame in json.loads((out / shard["metadata"]).read_text())["frames"]:
            assert frame["background"] == keys[frame["index"]]
            assert frame["seed"] == seeds[frame["background"]]
    assert manifest["fidelity"]["differential"]["value"] is True


def test_corrupt_background_is_rerendered_and_shards_are_identical(
    differential_dataset, differential_dataset_copy
):
    from mincam_render.data.render_job import render_dataset

    request, out, copy = TINY_DIFFERENTIAL, differential_dataset, differential_dataset_copy
    manifest = ds.read_manifest(copy)
    bg_file = copy / manifest["background_components"][1]["file"]
    bg_file.write_bytes(bg_file.read_bytes()[:-16])  # truncated
    for rec in manifest["shards"][1:]:
        (copy / rec["transport"]).unlink()
        (copy / rec["metadata"]).unlink()
    summary = render_dataset(request, copy, workers=1)
    assert summary.shards_rendered == [1, 2]
    for name in ("transport", "metadata"):
        for rec in ds.read_manifest(out)["shards"]:
            assert (copy / rec[name]).read_bytes() == (out / rec[name]).read_bytes()
    assert bg_file.read_bytes() == (out / bg_file.relative_to(copy)).read_bytes()


def test_differential_is_refused_for_families_without_background(tmp_path, variant):
    from mincam_render.data.render_job import RenderRequest, render_dataset

    request = RenderRequest(
        family="patches",
        num_frames=4,
        spp=1,
        max_depth=2,
        shared_render=False,
        dtype="float32",
        differential=True,
        overrides={"camera": {"mask_resolution": 4}},
    )
    with pytest.raises(ValueError, match="no static background"):
        render_dataset(request, tmp_path / "ds", workers=0)


def test_auto_fidelity_measures_and_records_the_differential_choice(variant):
    from mincam_render.data.render_job import RenderRequest
    from mincam_render.render.fidelity import decide_fidelity

    overrides = {"fps": 2.0, "camera": {"mask_resolution": 8, "detectors": 2}}
    request = RenderRequest(family="workspace", num_frames=600, overrides=overrides)
    fam = load_family("workspace", seed=0, num_frames=600, overrides=overrides)
    plan = decide_fidelity(fam, fam.camera(), request)
    settings, decisions = plan.settings(), plan.decisions
    d = decisions["differential"]
    assert d["source"] == "auto"
    assert d["backgrounds"] == len({fam.background_key(i, 60.0) for i in range(600)})
    assert d["value"] == (d["cost_per_frame"] < d["plain_cost_per_frame"])
    if not settings["shared_render"]:
        sd = d["shared_difference"]
        assert sd["value"] == (sd["parallax_error_rms"] < sd["bound"])
    if d["value"]:
        assert settings["background"]["spp"] == d["background_spp"]
        assert settings["spp"] == d["frame_spp"] == decisions["spp"]["value"]
        assert settings["max_depth"] == d["frame_max_depth"]
        assert settings["background"]["difference_seeds"] == d["difference_seeds"]["value"]
        assert "error_vs_reference" in d
    else:
        assert settings["background"] is None
    # every plan reports its error relative to the total and to the label signal
    figures = decisions["achieved"]["against_reference"]
    assert set(figures) >= {"total_relative", "signal_relative", "signal_relative_finest_box"}
    signal = decisions["achieved"]["label_signal_rms"]
    assert 0 < signal["random_masks_w"] and 0 < signal["finest_box_w"]


def test_ray_renders_differential_datasets_byte_identically(differential_dataset, tmp_path):
    pytest.importorskip("ray")
    from mincam_render.data.render_job import render_dataset

    request, out = TINY_DIFFERENTIAL, differential_dataset
    render_dataset(request, tmp_path / "ray", ray_address="local")
    for rec in ds.read_manifest(out)["shards"]:
        for name in ("transport", "metadata"):
            assert (tmp_path / "ray" / rec[name]).read_bytes() == (out / rec[name]).read_bytes()


def test_spp_rounds_up_at_most_a_quarter_octave_then_to_a_stratification_grid():
    from mincam_render.render.fidelity import PILOT_SPP
    from mincam_render.render.fidelity.budget import round_up_spp, spp_for

    assert round_up_spp(139, 4096, 4) == 168  # 160 on the grid, then 12 x 14
    assert round_up_spp(139, 4096, 1) == 256  # a whole octave
    assert round_up_spp(5000, 4096, 4) == 4096  # the cap
    for need in np.geomspace(1.0, 3000.0, 200):
        n = round_up_spp(need, 1 << 20, 4)
        assert need <= n <= 1.25 * need * (1 + 2 / np.sqrt(need)) + 1
        assert n % math.isqrt(n) == 0  # one pass of a full stratification grid
    # the plain estimator's spp: the smallest on that grid whose 1/sqrt(spp) error meets the target
    spp = spp_for(3.12, 0.53, 4096, steps_per_octave=4)
    assert 3.12 * math.sqrt(PILOT_SPP / spp) <= 0.53 < 3.12 * math.sqrt(PILOT_SPP / (0.75 * spp))


def test_noise_budget_split_is_the_cheapest_that_meets_the_target():
    """x^2 + y^2 + biases^2 = target^2, and no other split of the noises costs less."""
    from mincam_render.render.fidelity import PILOT_SPP, split_noise_budget

    target, biases = 0.01, {"depth": 0.004, "interp": 0.003}
    diff, bg = (0.0075, 4.0, None), (0.0975, 0.15, None)
    b = split_noise_budget(target, biases, diff, bg)
    x, y = b.difference_noise, b.background_noise
    assert x**2 + y**2 + 0.004**2 + 0.003**2 == pytest.approx(target**2)

    def cost(x):  # spp needed for noise x (continuous), times the cost per sample
        y = np.sqrt(target**2 - 0.004**2 - 0.003**2 - x**2)
        return PILOT_SPP * (diff[0] / x) ** 2 * diff[1] + PILOT_SPP * (bg[0] / y) ** 2 * bg[1]

    grid = np.linspace(0.05, 0.99, 500) * np.sqrt(target**2 - 0.004**2 - 0.003**2)
    assert cost(x) <= cost(grid).min() * (1 + 1e-6)
    assert not b.biases_exceed_target
    # a flag fixes one noise; the other takes the rest
    fixed = split_noise_budget(target, biases, (0.0075, 4.0, 16), bg)
    assert fixed.difference_noise == pytest.approx(0.0075 * np.sqrt(PILOT_SPP / 16))
    assert fixed.difference_noise**2 + fixed.background_noise**2 == pytest.approx(
        target**2 - 0.004**2 - 0.003**2
    )
    # biases beyond the target are reported, and the noises still get a floor
    over = split_noise_budget(target, {"depth": 0.02}, diff, bg)
    assert over.biases_exceed_target and over.difference_noise > 0


@pytest.mark.parametrize("empty_room", [False, True])
def test_converged_backgrounds_are_the_frames_without_their_movers(
    differential_dataset, tmp_path, empty_room
):
    from dataclasses import replace

    from mincam_render.data.render_job import render_dataset
    from mincam_render.data.render_job.backgrounds import converged_backgrounds

    request, out = TINY_DIFFERENTIAL, differential_dataset
    if empty_room:  # nobody comes in: every frame is its background, bit for bit
        request = replace(request, overrides={**request.overrides, **EMPTY_ROOM})
        out = tmp_path / "empty"
        render_dataset(request, out, workers=0)
    b = converged_backgrounds(out)
    t = ds.open_dataset(out).frames(0, 24)
    assert b.shape == t.shape and b.dtype == np.float32
    fam = load_family("workspace", seed=0, num_frames=24, overrides=request.overrides)
    for i in range(24):  # common random numbers: nothing moving, nothing added
        moving = fam.track.active[i].sum() > 0 or fam.track.door_angle_rad[i] != 0.0
        assert np.array_equal(t[i], b[i]) is not moving
        assert moving is not empty_room
    if empty_room:  # no movers: their signal is not measurable, its relative figures undefined
        achieved = ds.read_manifest(out)["fidelity"]["achieved"]
        assert achieved["label_signal_rms"]["random_masks_w"] == 0.0
        assert achieved["against_reference"]["signal_relative"] is None
        assert achieved["against_reference"]["total_relative"]["rms"] > 0


def test_converged_backgrounds_need_a_differential_dataset(tiny_patches):
    from mincam_render.data.render_job.backgrounds import converged_backgrounds

    with pytest.raises(ds.DatasetError, match="not rendered differentially"):
        converged_backgrounds(tiny_patches)


class _SeedEcho:
    """A stand-in family whose renders are their seed plus its state: 0 background, 1 frame."""

    def __init__(self) -> None:
        self.state = -1

    def background_key(self, index, interval_s):
        return "only"

    def background_components(self, index, interval_s):
        return {"light": 1.0}

    def set_background(self, scene, index, interval_s, *, at=0.0):
        self.state = 0

    def set_frame_in_window(self, scene, index, interval_s):
        self.state = 1
        return {"index": np.array([index], np.float32)}

    def render_transport(self, scene, camera, *, spp, seed, max_depth=None, parallax=True):
        return np.full((1, 2, 2), float(seed % 1000) + 100.0 * self.state)


@pytest.mark.parametrize("seeds", list(DifferenceSeeds))
def test_frames_share_the_windows_seed_or_have_their_own(seeds):
    from mincam_render.optics.camera import FreeformCamera

    fam = _SeedEcho()
    window_c = np.full((1, 2, 2), 7.0)  # C of the window: seed 7, background state
    bg = Background(
        key="only",
        interval_s=60.0,
        seed=7,
        components={"light": np.full((1, 2, 2), 1000.0)},
        same_seed_w=window_c,
        difference_seeds=seeds,
    )
    camera = FreeformCamera()
    frames = [render_frame(fam, None, camera, i, bg, spp=1, max_depth=None)[0] for i in range(4)]
    frame_seeds = [bg.frame_seed(i) for i in range(4)]
    for frame in frames:
        # B + X - C with one seed: the seeds cancel, the movers' change (100) remains
        np.testing.assert_array_equal(frame, np.full((1, 2, 2), 1100.0))
    if seeds is DifferenceSeeds.WINDOW:
        assert frame_seeds == [7] * 4
    else:
        assert len(set(frame_seeds)) == 4 and 7 not in frame_seeds


def test_unknown_difference_seeds_are_refused():
    with pytest.raises(ValueError, match="difference_seeds"):
        BackgroundSettings(interval_s=1.0, spp=4, max_depth=None, difference_seeds="episode")


def test_planning_against_a_signal_that_is_not_measurable_is_refused():
    from mincam_render.data.render_job import RenderRequest
    from mincam_render.render.fidelity import decide_fidelity
    from mincam_render.render.precision import UnmeasurableSignalError

    overrides = {"fps": 2.0, "camera": {"mask_resolution": 8, "detectors": 2}, **EMPTY_ROOM}
    request = RenderRequest(
        family="workspace", num_frames=24, overrides=overrides, error_scale="signal"
    )
    fam = load_family("workspace", seed=0, num_frames=24, overrides=overrides)
    with pytest.raises(UnmeasurableSignalError, match="label_signal"):
        decide_fidelity(fam, fam.camera(), request)


@pytest.mark.parametrize(
    ("floor", "blamed", "part"), [(1.5, "--spp", 0.765), (0.3, "--per-detector", 1.439)]
)
def test_a_missed_target_blames_sharing_only_for_its_change_above_two_seeds_noise(
    floor, blamed, part
):
    from mincam_render.render.fidelity.check import _knobs_to_turn
    from mincam_render.render.fidelity.records import Decision, Source

    measured = {
        "error_shared_vs_per_detector": {"rms": 1.47},
        "noise_floor_two_seeds": {"rms": floor},
    }
    decisions = {
        "shared_render": Decision(value=True, source=Source.AUTO, reason="", measured=measured),
        "max_depth": Decision(value=4, source=Source.AUTO, reason=""),
    }
    knobs = _knobs_to_turn(0.765, decisions, 0.53, 168, depth_in_scale=False)
    assert len(knobs) == 1 and knobs[0][0].startswith(blamed)
    assert knobs[0][1] == pytest.approx(part, abs=1e-3)  # 1.439 = sqrt(1.47^2 - 0.3^2)
