"""Scene description loading, the family registry and the patches family."""

import dataclasses
from pathlib import Path

import mitsuba as mi
import numpy as np
import pytest

from mincam_render import render_transport
from mincam_render.core.config import ConfigError, parse, spec
from mincam_render.render import mitsuba_scene as ms
from mincam_render.scenes import load_family
from mincam_render.scenes.patches import PLANE_RADIANCE_PARAM, PatchesConfig


@dataclasses.dataclass(frozen=True, kw_only=True)
class Inner:
    size_m: float = spec(1.0, unit="m", range=(0.0, 10.0))


@dataclasses.dataclass(frozen=True, kw_only=True)
class Outer:
    count: int = spec(3, range=(0, 8))
    name: str = spec("x")
    inner: Inner = spec(default_factory=Inner)
    pair: tuple[float, float] = spec((0.0, 1.0))


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ({"cuont": 3}, r"f.toml: unknown key 'cuont' in Outer; allowed: count, inner, name, pair"),
        ({"count": 9}, r"f.toml: count = 9: allowed range \[0, 8\]"),
        ({"count": 2.5}, r"f.toml: count = 2.5: expected an integer"),
        ({"count": True}, r"f.toml: count = True: expected an integer"),
        ({"inner": {"size_m": "4e-3"}}, r"f.toml: inner.size_m = '4e-3': expected a number in m"),
        ({"inner": {"size_m": -1.0}}, r"inner.size_m = -1.0: allowed range \[0.0, 10.0\] m"),
        ({"inner": {"size": 1.0}}, r"unknown key 'inner.size'"),
        ({"pair": [1.0]}, r"pair = \[1.0\]: expected an array of 2 values"),
        ({"name": 3}, r"name = 3: expected a string"),
    ],
)
def test_parse_rejects_bad_values_naming_file_field_and_reason(table, message):
    with pytest.raises(ConfigError, match=message):
        parse(Outer, table, source="f.toml")


def test_parse_builds_nested_defaults():
    out = parse(Outer, {"inner": {"size_m": 2}, "pair": [1, 2]}, source="f.toml")
    assert out == Outer(inner=Inner(size_m=2.0), pair=(1.0, 2.0))
    assert isinstance(out.inner.size_m, float)


@pytest.mark.parametrize("default", [Outer(), Outer(count=5, inner=Inner(size_m=7.0))])
def test_parse_reads_back_a_default_as_its_table(default):
    from mincam_render.core.config import _as_table

    assert parse(Outer, _as_table(default)) == default


def test_a_partial_nested_table_keeps_the_fields_defaults(tmp_path):
    """``[camera] detectors = 16`` alone: every other camera key keeps the family's default."""
    path = tmp_path / "sixteen.toml"
    path.write_text('family = "patches"\npatch_size = [0.10, 0.15]\n[camera]\ndetectors = 16\n')
    fam = load_family(path, seed=0, num_frames=3)
    want = dataclasses.replace(
        PatchesConfig(),
        patch_size=(0.10, 0.15),
        camera=dataclasses.replace(PatchesConfig().camera, detectors=16),
    )
    assert fam.config == want
    assert fam.camera().num_detectors == 16
    over = load_family("patches", seed=0, num_frames=3, overrides={"camera": {"detectors": 2}})
    assert over.config.camera == dataclasses.replace(PatchesConfig().camera, detectors=2)


def test_shipped_patches_description_matches_defaults():
    fam = load_family("patches", seed=0, num_frames=3)
    assert fam.config == PatchesConfig()


@pytest.mark.parametrize(
    ("toml", "message"),
    [
        ('family = "patches"\nmax_patches = -1\n', r"max_patches = -1: allowed range"),
        ('family = "patches"\npatch_size = [0.3, 0.1]\n', r"patch_size .*min must not exceed max"),
        (
            'family = "workspace"\n[people]\nwalk_speed_m_s = [1.4, 0.9]\n',
            r"walk_speed_m_s = \[1.4, 0.9\]: min must not exceed max",
        ),
        (
            'family = "traffic"\nbuilding_albedo = [0.5, 0.2]\n',
            r"building_albedo = \[0.5, 0.2\]: min must not exceed max",
        ),
        (
            'family = "patches"\nplane_distance_m = "1 m"\n',
            r"plane_distance_m = '1 m': expected a number",
        ),
        ('family = "patches"\n[camera]\nposition = [0, 0, 0]\nlook_at = [0, 0, 0]\n', r"look_at"),
        ('family = "nope"\n', r"unknown scene family 'nope'"),
        ("max_patches = 3\n", r"missing top-level key family"),
        ('family = "patches"\nmax_patches = [\n', r"not valid TOML"),
    ],
)
def test_bad_descriptions_are_rejected(tmp_path, toml, message):
    path = tmp_path / "bad.toml"
    path.write_text(toml)
    with pytest.raises((ConfigError, ValueError), match=message):
        load_family(path, seed=0, num_frames=2)


def test_missing_description_file(tmp_path):
    with pytest.raises(ConfigError, match="not found"):
        load_family(tmp_path / "none.toml", seed=0, num_frames=2)


def test_patches_labels_come_from_the_generated_state():
    fam = load_family("patches", seed=3, num_frames=200)
    counts = [fam.frame_state(i)["count"] for i in range(200)]
    assert set(counts) == set(range(0, 11))  # uniform over 0..10
    img, state = fam.image(5)
    assert len(state["patches"]) == state["count"]
    c = fam.config
    for p in state["patches"]:
        assert c.patch_size[0] <= min(p["size"]) and max(p["size"]) <= c.patch_size[1]
        assert c.patch_radiance_w_m2_sr[0] <= p["radiance"] <= c.patch_radiance_w_m2_sr[1]
    # the illumination only modulates: radiance stays within (1 +- A) of the painted levels
    amp = state["illumination"]["amplitude"]
    assert img.max() <= c.patch_radiance_w_m2_sr[1] * (1 + amp) + 1e-4
    assert img.min() >= 0.0


def test_patches_deterministic_for_a_seed_and_order_independent():
    a = load_family("patches", seed=1, num_frames=10)
    b = load_family("patches", seed=1, num_frames=10)
    c = load_family("patches", seed=2, num_frames=10)
    forward = [a.image(i)[0] for i in range(10)]
    backward = [b.image(i)[0] for i in reversed(range(10))][::-1]
    for x, y in zip(forward, backward, strict=True):
        np.testing.assert_array_equal(x, y)
    assert not np.array_equal(forward[0], c.image(0)[0])
    with pytest.raises(IndexError):
        a.image(10)


def test_patch_image_orientation_on_the_plane(variant):
    """A bright top-right quadrant of the plane image lands top-right in T."""
    fam = load_family("patches", seed=0, num_frames=1, overrides={"camera": {"detectors": 1}})
    scene = fam.build_scene()
    n = fam.config.image_resolution
    img = np.zeros((n, n), np.float32)
    img[: n // 2, n // 2 :] = 10.0
    params = mi.traverse(scene)
    params[PLANE_RADIANCE_PARAM] = ms.emitter_image_data(img)
    params.update()
    t = render_transport(scene, fam.camera(), spp=16)[0]
    rows, cols = t.shape
    assert t[: rows // 2, cols // 2 :].sum() > 0.95 * t.sum()


def test_set_frame_updates_in_place_and_more_patches_mean_more_light(variant):
    fam = load_family(
        "patches",
        seed=0,
        num_frames=60,
        overrides={
            "illumination_amplitude": [0.0, 0.0],
            "patch_radiance_w_m2_sr": [5.0, 5.0],
            "patch_size": [0.1, 0.1],
            "camera": {"detectors": 1, "mask_resolution": 16},
        },
    )
    scene = fam.build_scene()
    cam = fam.camera()
    by_count = {}
    for i in range(60):
        labels = fam.set_frame(scene, i)
        assert labels["count"].dtype == np.float32 and labels["count"].shape == (1,)
        by_count.setdefault(int(labels["count"][0]), []).append(i)
    lo, hi = min(by_count), max(by_count)
    fam.set_frame(scene, by_count[lo][0])
    p_lo = render_transport(scene, cam, spp=8)
    fam.set_frame(scene, by_count[hi][0])
    p_hi = render_transport(scene, cam, spp=8)
    assert p_hi.sum() > p_lo.sum()


def test_per_vertex_albedo_reflects_like_a_uniform_one(variant):
    """A floor of per-vertex albedo 0.6 under a uniform sky reflects 0.6 L, like albedo 0.6."""
    from mincam_render.optics.camera import FreeformCamera

    quad_v = np.array([[-50, -50, 0], [50, -50, 0], [50, 50, 0], [-50, 50, 0]], float)
    quad_f = np.array([[0, 1, 2], [0, 2, 3]])
    cam = FreeformCamera(
        position=(0.0, 0.0, 1.0), look_at=(0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0)
    ).centre_camera()
    cam = dataclasses.replace(cam, mask_resolution=(2, 2))
    out = []
    for albedo in (0.6, np.full(4, 0.6)):
        scene = {
            "type": "scene",
            "integrator": {"type": "path", "max_depth": 2},
            "sky": ms.constant_environment(1.0),
            "floor": ms.mesh("floor", quad_v, quad_f, reflectance=albedo),
        }
        out.append(render_transport(scene, cam, spp=4096, seed=1))
    np.testing.assert_allclose(out[1], out[0], rtol=1e-5)
    sky_only = render_transport(
        {
            "type": "scene",
            "integrator": {"type": "path", "max_depth": 2},
            "sky": ms.constant_environment(1.0),
        },
        cam,
        spp=4096,
        seed=1,
    )
    # 16k paths each: the sums agree to ~0.3 % (noise, over seeds 0-2)
    assert out[1].sum() == pytest.approx(0.6 * sky_only.sum(), rel=0.01)


def test_mesh_refuses_a_reflectance_of_the_wrong_size(variant):
    v = np.zeros((3, 3))
    v[1, 0] = v[2, 1] = 1.0
    with pytest.raises(ValueError, match="one per vertex"):
        ms.mesh("tri", v, [[0, 1, 2]], reflectance=[0.5, 0.5])


@dataclasses.dataclass(frozen=True, kw_only=True)
class WithFile:
    scene: Path = spec(doc="a file named in a description")


def test_file_paths_in_a_description_are_relative_to_its_folder(tmp_path):
    from mincam_render.core.config import load_toml, to_dict

    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "d.toml").write_text('scene = "../room.xml"\n')
    described = load_toml(WithFile, tmp_path / "sub" / "d.toml")
    assert described.scene == tmp_path / "room.xml"  # absolute: the dataset's workers find it
    assert parse(WithFile, to_dict(described)) == described  # a manifest reads it back
    with pytest.raises(ConfigError, match=r"scene = 3: expected a file path"):
        parse(WithFile, {"scene": 3})
