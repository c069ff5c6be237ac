"""Scenes users bring: units, the scene's own sensor pose, checks before and after a render."""

from __future__ import annotations

import json
import logging

import mitsuba as mi
import numpy as np
import pytest
from click.testing import CliRunner
from mitsuba_xml import scene_dict_to_xml

from mincam_render.cli.main import main
from mincam_render.optics.camera import DetectorLayout, FreeformCamera
from mincam_render.render import user_scene
from mincam_render.render.mitsuba_scene import SceneError, load_scene, scene_dict, sphere
from mincam_render.render.transport import render_transport, render_transport_with_noise

CORNELL_SENSOR_M = (0.0, 0.0, 3.9)  # mi.cornell_box(): sensor looks along -z from here


def _camera(position=CORNELL_SENSOR_M, look_at=(0.0, 0.0, 0.0), rows=2, cols=2, res=8):
    return FreeformCamera(
        mask_resolution=(res, res),
        layout=DetectorLayout.grid(rows=rows, cols=cols, pitch_m=0.02),
        position=position,
        look_at=look_at,
    )


def test_rescale_scene_scales_shapes_and_moves_the_sensor(variant):
    scene = load_scene(mi.cornell_box())
    user_scene.rescale_scene(scene, 1000.0)
    box = scene.bbox()
    assert np.allclose(list(box.min), [-1000, -1010, -1000], rtol=1e-5)
    assert np.allclose(list(box.max), [1000, 1000, 1000], rtol=1e-5)
    pose = user_scene.sensor_pose(scene)
    assert np.allclose(pose.position, (0, 0, 3900), rtol=1e-6)
    assert np.allclose(np.subtract(pose.look_at, pose.position), (0, 0, -1), atol=1e-6)


@pytest.mark.parametrize("factor", [0.0, -1.0, float("nan"), float("inf"), "1", True])
def test_rescale_scene_refuses_bad_factors(variant, factor):
    with pytest.raises(SceneError, match="scene scale"):
        user_scene.rescale_scene(load_scene(mi.cornell_box()), factor)


def test_sensor_pose_of_the_cornell_box_and_a_missing_id(variant):
    scene = load_scene(mi.cornell_box())
    pose = user_scene.sensor_pose(scene, "sensor")
    assert np.allclose(pose.position, CORNELL_SENSOR_M, atol=1e-6)
    assert np.allclose(pose.look_at, (0.0, 0.0, 2.9), atol=1e-6)
    assert np.allclose(pose.up, (0.0, 1.0, 0.0), atol=1e-6)
    with pytest.raises(SceneError, match=r"no sensor with id 'nope'.*\['sensor'\]"):
        user_scene.sensor_pose(scene, "nope")


def test_check_scene_without_emitter_errors_or_warns(variant, caplog):
    dark = load_scene(scene_dict({"ball": sphere((0.0, 0.0, 2.0), 0.5)}))
    with pytest.raises(SceneError, match="no emitter"):
        user_scene.check_scene(
            dark, _camera((0.0, 0.0, 0.0), (0.0, 0.0, 1.0)), require_emitter=True
        )
    with caplog.at_level(logging.WARNING):
        warned = user_scene.check_scene(
            dark, _camera((0.0, 0.0, 0.0), (0.0, 0.0, 1.0)), require_emitter=False
        )
    assert len(warned) == 1 and "no emitter" in caplog.text


def test_check_scene_refuses_a_camera_far_from_the_scene(variant):
    scene = load_scene(mi.cornell_box())
    with pytest.raises(SceneError, match=r"1e\+30 m from the scene.*--position"):
        user_scene.check_scene(
            scene, _camera((1e30, 0.0, 0.0), (0.0, 0.0, 0.0)), require_emitter=True
        )
    assert user_scene.check_scene(scene, _camera(), require_emitter=True) == []


def test_check_transport_names_dark_detectors_and_refuses_all_dark(variant):
    scene = load_scene(mi.cornell_box())
    t = np.ones((4, 2, 2), dtype=np.float32)
    t[[1, 3]] = 0.0
    (message,) = user_scene.check_transport(t, scene)
    assert "2 of 4 detectors" in message and "[1, 3]" in message
    with pytest.raises(SceneError, match=r"all 4 detectors see no light.*found 1 AreaLight\)"):
        user_scene.check_transport(np.zeros((4, 2, 2)), scene)
    assert user_scene.check_transport(np.ones((4, 2, 2)), scene) == []


def test_noise_estimate_matches_the_spread_over_seeds(variant):
    """Relative error from within-texel spread vs the spread of 20 independent renders.

    At 64 spp the two agreed within 20 % when measured over 40 seeds; 20 seeds
    know the truth to about +-16 %, hence the band.
    """
    scene, camera = load_scene(mi.cornell_box()), _camera(res=8)
    totals, estimates = [], []
    for seed in range(20):
        t, relative = render_transport_with_noise(scene, camera, spp=64, seed=seed)
        totals.append(t.sum(axis=(1, 2)))
        estimates.append(relative)
    totals = np.array(totals)
    empirical = totals.std(axis=0, ddof=1) / totals.mean(axis=0)
    ratio = np.sqrt(np.mean(np.square(estimates), axis=0)) / empirical
    assert np.all((ratio > 0.65) & (ratio < 1.6)), ratio
    same = render_transport(scene, camera, spp=64, seed=0)
    np.testing.assert_array_equal(same.sum(axis=(1, 2)), totals[0])


def test_spp_for_noise_follows_inverse_square_root():
    assert user_scene.spp_for_noise(16, np.array([0.2, 0.05, np.nan])) == 16 * 400
    assert user_scene.spp_for_noise(16, np.array([0.001])) == 1
    assert user_scene.spp_for_noise(4, np.array([np.nan])) == 1


def _transport(tmp_path, name, scene_file, *args):
    out = tmp_path / name
    res = CliRunner().invoke(
        main,
        ["transport", str(scene_file), "--out", str(out), "--pose-from-sensor", "--spp", "16"]
        + ["--mask-res", "8", "--grid", "2x2", *args],
    )
    assert res.exit_code == 0, res.output
    return json.loads((out / "config.json").read_text())


def _detector_power(config, tmp_path, name):
    from mincam_render.data.exr import read_transport_exr

    t, _ = read_transport_exr(tmp_path / name / "transport.exr")
    return t.sum(axis=(1, 2)).astype(np.float64)


def test_millimetre_cornell_box_warns_and_scene_scale_gives_metre_measurements(
    variant, tmp_path, caplog
):
    """The issue's acceptance case: mi.cornell_box() in metres vs the same box in mm."""
    scene_dict_to_xml(mi.cornell_box(), tmp_path / "box_m.xml")
    scene_dict_to_xml(mi.cornell_box(), tmp_path / "box_mm.xml", length_scale=1000.0)
    metre = _transport(tmp_path, "m", tmp_path / "box_m.xml")
    assert metre["warnings"] == [] or all("relative error" in w for w in metre["warnings"])
    with caplog.at_level(logging.WARNING):
        unscaled = _transport(tmp_path, "mm", tmp_path / "box_mm.xml")
    assert any("is it in millimetres? pass --scene-scale 0.001" in w for w in unscaled["warnings"])
    assert "--scene-scale 0.001" in caplog.text
    scaled = _transport(tmp_path, "mm_scaled", tmp_path / "box_mm.xml", "--scene-scale", "0.001")
    assert not any("millimetres" in w for w in scaled["warnings"])
    assert np.allclose(scaled["camera"]["position"], CORNELL_SENSOR_M, atol=1e-5)
    p_m, p_mm = (
        _detector_power(metre, tmp_path, "m"),
        _detector_power(scaled, tmp_path, "mm_scaled"),
    )
    sigma = np.array(metre["relative_noise"]) * p_m
    assert np.all(np.abs(p_mm - p_m) <= 3 * np.sqrt(2) * sigma), (p_m, p_mm, sigma)


def test_cli_transport_refuses_a_scene_without_emitter_and_conflicting_pose(variant, tmp_path):
    scene_dict_to_xml(scene_dict({"ball": sphere((0.0, 0.0, 2.0), 0.5)}), tmp_path / "dark.xml")
    runner = CliRunner()
    res = runner.invoke(
        main, ["transport", str(tmp_path / "dark.xml"), "--out", str(tmp_path / "o")]
    )
    assert res.exit_code != 0 and "no emitter" in res.output and "Traceback" not in res.output
    assert not (tmp_path / "o").exists()
    cornell = tmp_path / "box.xml"
    scene_dict_to_xml(mi.cornell_box(), cornell)
    both = runner.invoke(
        main, ["transport", str(cornell), "--pose-from-sensor", "--position", "0,0,1"]
    )
    assert both.exit_code == 2 and "drop --position" in both.output
    alone = runner.invoke(main, ["transport", str(cornell), "--sensor-id", "sensor"])
    assert alone.exit_code == 2 and "--sensor-id needs --pose-from-sensor" in alone.output
    far = runner.invoke(main, ["transport", str(cornell), "--position", "1e30,0,0"])
    assert far.exit_code != 0 and "--position" in far.output


def _point_light_xml(tmp_path, z_m: float, *, ball: bool):
    scene = {
        "type": "scene",
        "lamp": {"type": "point", "position": [0.0, 0.0, z_m], "intensity": 10.0},
    }
    if ball:  # lit from the front, it sends some light back to the board
        scene["ball"] = sphere((0.0, 0.0, 1.0), 0.2, bsdf={"type": "diffuse"})
    path = tmp_path / f"lamp_{z_m:+g}.xml"
    scene_dict_to_xml(scene, path)
    return scene, path


def test_cli_counts_a_point_light_in_front_and_names_it_when_behind(variant, tmp_path):
    """The issue's case: a point light (10 W/sr) 0.5 m in front of the board, a sphere
    behind it. Its direct light (~3.1e-5 W per detector, I A / r^2) was dropped,
    leaving 7e-7 W bounced off the sphere; now the CLI's power is the API's.
    Behind the board, the error names the point light it found."""
    scene, path = _point_light_xml(tmp_path, 0.5, ball=True)
    res = CliRunner().invoke(
        main, ["transport", str(path), "--out", str(tmp_path / "o"), "--grid", "2x2"]
        + ["--mask-res", "8", "--spp", "16"],
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    cam = _camera((0.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    power = _detector_power(None, tmp_path, "o")
    expected = render_transport(load_scene(scene), cam, spp=16, seed=0).sum(axis=(1, 2))
    np.testing.assert_allclose(power, expected, rtol=1e-6)
    direct = 10.0 * cam.detector_size_m**2 / 0.5**2
    assert np.all((power > direct) & (power < 1.1 * direct)), (power, direct)
    _, behind = _point_light_xml(tmp_path, -0.5, ball=False)
    res = CliRunner().invoke(main, ["transport", str(behind), "--out", str(tmp_path / "b")])
    assert res.exit_code != 0 and "Traceback" not in res.output
    assert "all 24 detectors see no light" in res.output and "found 1 PointLight" in res.output
