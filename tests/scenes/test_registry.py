"""Families from outside the package: entry points, ``module:Class``, and what they declare."""

from __future__ import annotations

import sys
import textwrap

import numpy as np
import pytest

from mincam_render.core.config import ConfigError
from mincam_render.render.capabilities import (
    DifferentialBackground,
    PeopleRemoval,
    Preview,
    SunlitWindow,
    TemporalLabels,
    history_frames,
)
from mincam_render.scenes import load_family
from mincam_render.scenes.registry import (
    ENTRY_POINT_GROUP,
    family_class,
    family_reference,
    known_families,
)

#: A family outside mincam_render: a lamp in front of the camera, on or off each frame.
BLINK = """
from dataclasses import dataclass

import mitsuba as mi
import numpy as np

from mincam_render.core.config import spec
from mincam_render.core.labels import LabelKind, LabelSpec
from mincam_render.render import mitsuba_scene as ms
from mincam_render.render.capabilities import DifferentialBackground
from mincam_render.scenes import CameraMount, SceneFamily


@dataclass(frozen=True, kw_only=True)
class BlinkConfig:
    fps: float = spec(10.0, unit="1/s", range=(1.0, 100.0), doc="frame rate")
    radiance_w_m2_sr: float = spec(5.0, unit="W m^-2 sr^-1", range=(0.0, 1e6), doc="lamp on")
    camera: CameraMount = spec(
        default_factory=lambda: CameraMount(
            position=(0.0, 0.0, 0.0), look_at=(0.0, 0.0, 1.0), up=(0.0, 1.0, 0.0),
            detectors=2, mask_resolution=8,
        ),
        doc="camera pose",
    )


class BlinkFamily(SceneFamily):
    name = "blink"
    config_type = BlinkConfig

    def __init__(self, config, *, seed, num_frames):
        super().__init__(config, seed=seed, num_frames=num_frames)
        self.on = np.random.default_rng(seed).random(num_frames) < 0.5

    @property
    def fps(self):
        return self.config.fps

    @property
    def labels(self):
        return (LabelSpec(name="on", kind=LabelKind.BINARY, median_filter_s=0.0),)

    def camera(self):
        return self.config.camera.camera()

    def build_scene(self):
        lamp = ms.rectangle((0, 0, 1), (0, 0, 0), (1, 1), radiance_w_m2_sr=1.0)
        return ms.load_scene(ms.scene_dict({"lamp": lamp}, max_depth=2))

    def set_frame(self, scene, index):
        self.check_index(index)
        params = mi.traverse(scene)
        value = self.config.radiance_w_m2_sr if self.on[index] else 0.0
        params["lamp.emitter.radiance.value"] = mi.Float(value)
        params.update()
        return {"on": np.array([self.on[index]], np.float32)}

    def frame_state(self, index):
        return {"on": bool(self.on[index])}


class TemporalBlink(BlinkFamily):
    name = "temporal_blink"
    history_frames = 5


class Unfinished(SceneFamily):
    name = "unfinished"
    config_type = BlinkConfig


class Background(BlinkFamily, DifferentialBackground):
    name = "background"

"""


@pytest.fixture(scope="module")
def outside(tmp_path_factory):
    """A package ``blinkpkg`` outside mincam_render, registering ``blink`` as an entry point."""
    root = tmp_path_factory.mktemp("site")
    (root / "blinkpkg").mkdir()
    (root / "blinkpkg" / "__init__.py").write_text("")
    (root / "blinkpkg" / "family.py").write_text(textwrap.dedent(BLINK))
    info = root / "blinkpkg-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: blinkpkg\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(
        f"[{ENTRY_POINT_GROUP}]\nblink = blinkpkg.family:BlinkFamily\n"
        "wrong = blinkpkg.family:TemporalBlink\npatches = blinkpkg.family:BlinkFamily\n"
    )
    sys.path.insert(0, str(root))
    yield root
    sys.path.remove(str(root))
    for name in [m for m in sys.modules if m.startswith("blinkpkg")]:
        del sys.modules[name]


def test_an_entry_point_family_is_found_by_name_with_its_defaults(outside, variant):
    assert "blink" in known_families()
    fam = load_family("blink", seed=1, num_frames=6)
    assert type(fam).__module__ == "blinkpkg.family" and fam.config.fps == 10.0
    assert family_reference(type(fam)) == "blink"  # what a dataset records for its workers
    scene = fam.build_scene()
    labels = [fam.set_frame(scene, i)["on"][0] for i in range(6)]
    assert labels == [float(v) for v in fam.on]


def test_a_description_names_a_family_class_directly(outside, tmp_path, variant):
    path = tmp_path / "lamp.toml"
    path.write_text('family = "blinkpkg.family:TemporalBlink"\nradiance_w_m2_sr = 2.5\n')
    fam = load_family(path, seed=0, num_frames=3, overrides={"fps": 20.0})
    assert (fam.config.radiance_w_m2_sr, fam.config.fps) == (2.5, 20.0)
    # its own name leads to no class: datasets name it by module and class
    assert family_reference(type(fam)) == "blinkpkg.family:TemporalBlink"
    assert family_class(family_reference(type(fam))) is type(fam)


def test_the_entry_point_family_descriptions_say_so(outside, tmp_path):
    path = tmp_path / "lamp.toml"
    path.write_text('family = "blink"\nradiance_w_m2_sr = -1.0\n')
    with pytest.raises(ConfigError, match=r"lamp.toml: radiance_w_m2_sr = -1.0: allowed range"):
        load_family(path, seed=0, num_frames=3)


@pytest.mark.parametrize(
    ("reference", "message"),
    [
        ("nosuch", r"unknown scene family 'nosuch'; known: patches, .*mitsuba, blink"),
        ("nosuchpkg.family:Family", r"cannot import 'nosuchpkg.family'"),
        ("blinkpkg.family:Nothing", r"module 'blinkpkg.family' has no 'Nothing'"),
        ("blinkpkg.family:BlinkConfig", r"is not a SceneFamily subclass"),
        ("blinkpkg.family:Unfinished", r"does not implement build_scene, camera, fps, frame_s"),
        ("wrong", r"loads blinkpkg.family:TemporalBlink, whose name is 'temporal_blink'"),
    ],
)
def test_a_family_that_cannot_be_used_is_named_with_the_reason(outside, reference, message):
    with pytest.raises(ConfigError, match=message):
        family_class(reference)


def test_an_entry_point_cannot_take_a_built_in_name(outside, caplog):
    from mincam_render.scenes.patches import PatchesFamily

    assert family_class("patches") is PatchesFamily
    assert known_families().count("patches") == 1
    assert "a built-in family's name" in caplog.text


def test_built_in_families_declare_their_capabilities():
    caps = (DifferentialBackground, PeopleRemoval, SunlitWindow, TemporalLabels, Preview)
    # a protocol checks members by name, so the class stands for its instances
    declared = {
        name: {c.__name__ for c in caps if isinstance(family_class(name), c)}
        for name in ("patches", "workspace", "lighting", "traffic")
    }
    indoor = {"DifferentialBackground", "PeopleRemoval", "SunlitWindow", "Preview"}
    assert declared == {
        "patches": {"Preview"},
        "workspace": indoor,
        "lighting": indoor,
        "traffic": {"TemporalLabels", "Preview"},
    }
    assert [history_frames(family_class(n)) for n in ("patches", "traffic")] == [1, 30]


def test_a_capability_stated_but_not_implemented_fails_at_instantiation(outside):
    from blinkpkg.family import Background, BlinkConfig

    with pytest.raises(TypeError, match="abstract methods background_components"):
        Background(BlinkConfig(), seed=0, num_frames=2)


def test_the_renderer_decides_from_what_a_family_declares(outside, tmp_path, variant):
    """No differential background: refused when asked, planned without otherwise; a
    temporal family's history reaches the dataset; no bird's-eye view: two columns."""
    from mincam_render.analysis.preview import _view_sensors
    from mincam_render.data.dataset import open_dataset
    from mincam_render.data.render_job import RenderRequest, render_dataset
    from mincam_render.learn.training_data import TrainingData

    ask = RenderRequest(family="blink", num_frames=4, spp=1, differential=True)
    with pytest.raises(ValueError, match="'blink' has no static background"):
        render_dataset(ask, tmp_path / "a", workers=0)
    request = RenderRequest(family="blinkpkg.family:TemporalBlink", num_frames=12, spp=1,
                            shard_frames=4)  # fmt: skip
    render_dataset(request, tmp_path / "b", workers=0)
    data = open_dataset(tmp_path / "b")
    family = data.manifest["family"]
    assert (family["name"], family["history_frames"], family["needs_history"]) == (
        "temporal_blink",
        5,
        True,
    )
    assert data.manifest["job"]["family"]["name"] == "blinkpkg.family:TemporalBlink"
    assert not data.manifest["fidelity"]["differential"]["value"]
    assert TrainingData.from_dataset(data, "train").history == 5  # what training reads
    on = np.asarray(data.labels((0, 12))["on"])[:, 0]
    power = data.transport((0, 12)).sum(axis=(1, 2, 3))
    assert np.all((power > 0) == (on > 0.5))  # the lamp's state is what the camera sees
    sensors = _view_sensors(load_family("blink", seed=0, num_frames=2), 8)
    assert list(sensors) == ["camera view"]
