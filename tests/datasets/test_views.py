"""Full views of a dataset's frames (privacy audit): the episode's own states, reuse, bad input."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from mincam_render.data import dataset as ds
from mincam_render.data.views import render_views, view_paths

FRAMES = 6


@pytest.fixture(scope="module")
def tiny(tmp_path_factory, variant):
    """6 patches frames, 1 detector, 4x4 masks, rendered in this process.

    Not conftest's ``tiny_patches`` (24 frames): every frame's view is rendered
    again by each test here, so the episode is kept to 6 frames.
    """
    from mincam_render.data.render_job import RenderRequest, render_dataset

    out = tmp_path_factory.mktemp("views") / "ds"
    request = RenderRequest(
        family="patches",
        num_frames=FRAMES,
        seed=5,
        overrides={"camera": {"detectors": 1, "mask_resolution": 4}},
        shard_frames=3,
        spp=1,
        shared_render=False,
        dtype="float32",
    )
    render_dataset(request, out, workers=0)
    return out


def test_views_are_the_episodes_frames_from_the_cameras_pose(tiny, tmp_path):
    import mitsuba as mi

    from mincam_render.render import mitsuba_scene as ms
    from mincam_render.scenes.registry import load_family

    views = render_views(tiny, tmp_path, width=8, spp=2)
    assert views.shape == (FRAMES, 8, 8) and views.dtype == np.float32
    assert np.all(np.isfinite(views)) and views.max() > 0
    # the same frames rendered directly from the family of the dataset's seed
    data = ds.open_dataset(tiny)
    family = load_family("patches", seed=5, num_frames=FRAMES,
                         overrides={"camera": {"detectors": 1, "mask_resolution": 4}})  # fmt: skip
    cam = data.camera
    sensor = ms.perspective_sensor(cam.position, cam.look_at, cam.up, cam.fov_deg, 8, 8)
    scene = family.build_scene()
    for i in (0, FRAMES - 1):
        family.set_frame(scene, i)
        direct = np.asarray(mi.render(scene, sensor=sensor, spp=2, seed=i))[..., 0]
        np.testing.assert_allclose(views[i], direct, rtol=1e-6, atol=0)
    # frames differ (patches move): the views follow the episode, not one state
    assert not np.allclose(views[0], views[-1])
    meta = json.loads(view_paths(tmp_path, 8)[1].read_text())
    assert meta["width"] == 8 and meta["spp"] == 2 and meta["unit"] == "W/(m^2 sr)"


def test_finished_views_are_reused_and_checked(tiny, tmp_path):
    first = np.array(render_views(tiny, tmp_path, width=8, spp=1))
    npy = view_paths(tmp_path, 8)[0]
    stamp = npy.stat().st_mtime_ns
    again = render_views(tiny, tmp_path, width=8, spp=1)
    assert npy.stat().st_mtime_ns == stamp  # not rendered again
    np.testing.assert_array_equal(first, again)
    with pytest.raises(ValueError, match="other settings"):
        render_views(tiny, tmp_path, width=8, spp=3)
    os.utime(npy)
    npy.write_bytes(npy.read_bytes()[:-4] + b"\0\0\0\1")  # damaged: rendered again
    np.testing.assert_array_equal(render_views(tiny, tmp_path, width=8, spp=1), first)


@pytest.mark.parametrize(("kw", "name"), [({"width": 0}, "width"), ({"spp": 1.5}, "spp")])
def test_bad_view_settings(tiny, tmp_path, kw, name):
    with pytest.raises(ValueError, match=name):
        render_views(tiny, tmp_path, **kw)


def test_a_family_without_people_to_remove_has_no_backgrounds(tiny, tmp_path):
    with pytest.raises(ValueError, match="cannot remove its people"):
        render_views(tiny, tmp_path, width=4, spp=1, people=False)
    assert not view_paths(tmp_path, 4, people=False)[0].exists()


#: A workspace of 1 fps from frame 0 with people inside (burn-in), 1 detector, 4x4 masks.
OFFICE = {"fps": 1.0, "burn_in_s": 120.0, "camera": {"detectors": 1, "mask_resolution": 4}}


@pytest.fixture(scope="module")
def office(tmp_path_factory, variant):
    """Its own dataset: a workspace with people in every frame (what removing them needs)."""
    from mincam_render.data.render_job import RenderRequest, render_dataset
    from mincam_render.render.fidelity.plan import Fidelity

    out = tmp_path_factory.mktemp("office") / "ds"
    request = RenderRequest(family="workspace", num_frames=3, seed=2, overrides=OFFICE,
                            shard_frames=3, spp=1, max_depth=2, fidelity=Fidelity.FULL)  # fmt: skip
    render_dataset(request, out, workers=0)
    return out


def test_backgrounds_are_the_frames_without_their_people_and_kept_on_disk(office, tmp_path):
    import mitsuba as mi

    from mincam_render.render import mitsuba_scene as ms
    from mincam_render.scenes.registry import load_family

    views = np.array(render_views(office, tmp_path, width=12, spp=2))
    background = np.array(render_views(office, tmp_path, width=12, spp=2, people=False))
    family = load_family("workspace", seed=2, num_frames=3, overrides=OFFICE)
    cam = ds.open_dataset(office).camera
    sensor = ms.perspective_sensor(cam.position, cam.look_at, cam.up, cam.fov_deg, 12, 12)
    scene = family.build_scene()
    for i in range(3):
        assert family.state(i).people
        family.set_frame_without_people(scene, i)
        direct = np.asarray(mi.render(scene, sensor=sensor, spp=2, seed=i))[..., 0]
        np.testing.assert_array_equal(background[i], direct)
    # the frame's seed in both: only the pixels the people touch differ
    assert 0.0 < np.mean(views != background) < 0.5
    npy, meta = view_paths(tmp_path, 12, people=False)
    assert npy.name == "background_12.npy" and json.loads(meta.read_text())["people"] == "removed"
    stamp = npy.stat().st_mtime_ns
    np.testing.assert_array_equal(render_views(office, tmp_path, width=12, spp=2, people=False),
                                  background)  # fmt: skip
    assert npy.stat().st_mtime_ns == stamp  # reused, not rendered again
    with pytest.raises(ValueError, match="other settings"):
        render_views(office, tmp_path, width=12, spp=1, people=False)
