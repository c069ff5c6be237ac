"""The declarative family of a user's Mitsuba scene (``family = "mitsuba"``)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from mincam_render.cli.main import main
from mincam_render.core.config import ConfigError
from mincam_render.render.capabilities import history_frames
from mincam_render.scenes import load_family

REPO = Path(__file__).resolve().parents[2]
TABLE = REPO / "examples" / "table_objects" / "table.toml"
XML = TABLE.parent / "table.xml"

#: A small description of the example's scene: a ball driven round a loop on the desk.
LOOP = f"""
family = "mitsuba"
scene = "{XML}"
fps = 4.0
[camera]
position = [0.0, 0.0, 2.2]
look_at = [0.0, 0.0, 0.77]
up = [0.0, 1.0, 0.0]
detectors = 2
mask_resolution = 8
[[movers]]
id = "ball"
path = [[-0.3, -0.2, 0.85], [0.3, -0.2, 0.85], [0.3, 0.2, 0.85], [-0.3, 0.2, 0.85]]
speed_m_s = [0.2, 0.2]
[[emitters]]
id = "desk_lamp"
mean_on_s = 2.0
mean_off_s = 2.0
[[labels]]
name = "x"
kind = "position"
mover = "ball"
axis = "x"
[[labels]]
name = "speed"
kind = "speed"
mover = "ball"
[[labels]]
name = "left"
kind = "count_in_region"
region = {{ min_m = [-0.5, -0.35, 0.77], max_m = [0.0, 0.35, 1.0] }}
"""


def _write(tmp_path: Path, text: str, name: str = "task.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _shape_centre(scene, shape_id: str) -> np.ndarray:
    (shape,) = [s for s in scene.shapes() if s.id() == shape_id]
    box = shape.bbox()
    return (np.array(box.min) + np.array(box.max)) / 2


def test_labels_are_computed_from_the_state_the_scene_is_set_to(variant):
    fam = load_family(TABLE, seed=3, num_frames=120)
    assert [s.name for s in fam.labels] == ["objects", "lamp"]
    assert fam.labels[1].element_names == ("desk_lamp",)
    scene = fam.build_scene()
    counts = []
    for index in (0, 37, 80, 119):
        labels = fam.set_frame(scene, index)
        state = fam.frame_state(index)
        present = [k for k, m in state["movers"].items() if m["present"]]
        assert labels["objects"][0] == len(present)  # every mover's region is on the desk
        assert labels["lamp"][0] == float(state["emitters_on"]["desk_lamp"])
        for key, mover in state["movers"].items():
            centre = _shape_centre(scene, key)
            if mover["present"]:  # the shape stands where the state says
                np.testing.assert_allclose(centre, mover["position_m"], atol=1e-5)
        counts.append(len(present))
    assert len(set(fam.label_values["objects"][:, 0])) > 1  # objects come and go


def test_a_hidden_mover_is_gone_from_the_render(variant, tmp_path):
    """Movers removed render as the scene file without them: same paths, same bits."""
    from mincam_render.render.transport import render_transport

    fam = load_family(TABLE, seed=0, num_frames=4, overrides={"camera": {"detectors": 2}})
    text = XML.read_text()
    for mover in ("book", "box", "ball", "mug"):
        text = re.sub(rf'  <shape type="\w+" id="{mover}">.*?</shape>\n', "", text, flags=re.S)
    bare = _write(tmp_path, text, "bare.xml")
    cam = fam.camera()
    scene = fam.build_scene()
    fam.set_frame_without_people(scene, 0)
    empty = load_family(TABLE, seed=0, num_frames=4,
                        overrides={"camera": {"detectors": 2}, "scene": str(bare), "movers": [],
                                   "labels": [{"name": "lamp", "kind": "emitter_on"}]})  # fmt: skip
    bare_scene = empty.build_scene()
    empty.set_frame(bare_scene, 0)
    a = render_transport(scene, cam, spp=4, seed=7, max_depth=3)
    b = render_transport(bare_scene, cam, spp=4, seed=7, max_depth=3)
    np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-12)


def test_background_components_add_up_to_the_background(variant):
    """Each switched emitter alone plus the static ones is the background (linear in light)."""
    from mincam_render.render.transport import render_transport

    fam = load_family(TABLE, seed=0, num_frames=400, overrides={"camera": {"detectors": 1}})
    on = int(np.flatnonzero(fam.switches[:, 0])[0])
    assert fam.background_components(on, 60.0) == {"static": 1.0, "emitter=desk_lamp": 1.0}
    assert fam.background_key(on, 60.0) == "emitters=1"
    scene, cam = fam.build_scene(), fam.camera()

    def total(setter) -> float:
        setter()
        return float(render_transport(scene, cam, spp=64, seed=1, max_depth=3).sum())

    background = total(lambda: fam.set_background(scene, on, 60.0))
    static = total(lambda: fam.set_background_component(scene, "static"))
    lamp = total(lambda: fam.set_background_component(scene, "emitter=desk_lamp"))
    assert lamp > 0.05 * static  # the desk lamp adds light the camera sees
    assert static + lamp == pytest.approx(background, rel=0.03)
    with pytest.raises(ValueError, match="not a background component"):
        fam.set_background_component(scene, "emitter=sun")


def test_a_path_mover_reports_its_position_and_speed_and_needs_history(variant, tmp_path):
    fam = load_family(_write(tmp_path, LOOP), seed=1, num_frames=80)
    assert history_frames(fam) == 4  # history_s = 1 s at 4 fps
    speed = fam.label_values["speed"][:, 0]
    # 0.2 m/s along the loop; cutting a corner between two frames covers a little less
    assert np.median(speed) == pytest.approx(0.2, rel=1e-5) and speed.min() > 0.7 * 0.2
    x = fam.label_values["x"][:, 0]
    assert x.min() >= -0.3 - 1e-6 and x.max() <= 0.3 + 1e-6 and np.ptp(x) > 0.5
    left = fam.label_values["left"][:, 0]
    np.testing.assert_array_equal(left, (x <= 0.0).astype(np.float32))
    specs = {s.name: s for s in fam.labels}
    assert (specs["speed"].unit, specs["x"].unit, specs["left"].kind.value) == ("m/s", "m", "count")


def test_differential_and_plain_datasets_of_a_user_scene_agree(variant, tmp_path):
    """The renderer composes a user scene's background like a shipped family's."""
    from mincam_render.data.dataset import open_dataset
    from mincam_render.data.render_job import RenderRequest, render_dataset

    common = {
        "family": str(TABLE), "num_frames": 8, "shard_frames": 8, "spp": 64, "max_depth": 3,
        "shared_render": False, "dtype": "float32", "overrides": {"camera": {"detectors": 2}},
    }  # fmt: skip
    render_dataset(RenderRequest(**common, differential=False), tmp_path / "plain", workers=0)
    differential = {"differential": True, "background_spp": 256, "shared_difference": False}
    render_dataset(RenderRequest(**common, **differential), tmp_path / "diff", workers=0)
    plain, diff = (open_dataset(tmp_path / n) for n in ("plain", "diff"))
    assert diff.manifest["job"]["family"]["name"] == "mitsuba"
    assert len(diff.manifest["background_components"]) >= 1
    a, b = plain.transport((0, 8)).sum(axis=(2, 3)), diff.transport((0, 8)).sum(axis=(2, 3))
    np.testing.assert_allclose(b, a, rtol=0.03)  # per frame and detector, within the noise
    for name in ("objects", "lamp"):
        np.testing.assert_array_equal(plain.labels((0, 8))[name], diff.labels((0, 8))[name])


BAD = {
    "unknown shape id": (
        ('id = "book"', 'id = "bok"'),
        r"movers\[0\]\.id = 'bok': no shape with this id in table\.xml \(shapes: ball, book,",
    ),
    "a region outside the scene": (
        (
            "min_m = [-0.35, -0.24, 0.785], max_m = [0.35, 0.24, 0.785]",
            "min_m = [4.6, -0.24, 0.785], max_m = [5.4, 0.24, 0.785]",
        ),
        r"movers\[0\]\.region = \{min_m = \[4.6, -0.24, 0.785\], max_m = \[5.4, 0.24, 0.785\]\}: "
        r"outside the scene, whose bounding box spans \[-2.0, -2.0, 0.0\] to \[2.0, 2.0, 2.6\] m",
    ),
    "a label's region outside the scene": (
        (
            "[-0.5, -0.35, 0.77], max_m = [0.5, 0.35, 1.0]",
            "[-0.5, -0.35, 0.77], max_m = [0.5, 0.35, 10.0]",
        ),
        r"labels\[0\]\.region = \{min_m = \[-0.5, -0.35, 0.77\], max_m = \[0.5, 0.35, 10.0\]\}: "
        r"outside the scene",
    ),
    "a box whose min exceeds its max": (
        ("min_m = [-0.35, -0.24, 0.785]", "min_m = [-0.35, -0.24, 7.85]"),
        r"movers\[0\]\.region: min_m = \[-0.35, -0.24, 7.85\], max_m = .*min must not exceed",
    ),
    "a label of a kind that does not exist": (
        ('kind = "count_in_region"', 'kind = "count_on_table"'),
        r"labels\[0\]\.kind = 'count_on_table': allowed values: 'count_in_region', "
        r"'emitter_on', 'position', 'speed'",
    ),
    "a mover that never enters the view": (
        (
            "position = [0.0, 0.0, 1.77]\nlook_at = [0.0, 0.0, 0.77]",
            "position = [1.9, 1.9, 0.3]\nlook_at = [1.9, 1.9, 0.0]",
        ),
        r"movers\[0\] \('book'\): never enters the camera's view",
    ),
    "a label naming a mover that is not described": (
        ('name = "objects"', 'name = "objects"\nmovers = ["book", "cup"]'),
        r"labels\[0\]\.movers\[1\] = 'cup': no mover with this id in the description",
    ),
    "an emitter the scene lacks": (
        ('"desk_lamp"', '"desk_lam"'),  # in [[emitters]] and in the label
        r"emitters\[0\]\.id = 'desk_lam': no emitter \(or shape with one\) with this id",
    ),
    "a field another kind needs": (
        ('emitters = ["desk_lamp"]', 'emitters = ["desk_lamp"]\nmover = "book"'),
        r"labels\[1\]: mover: not a field of kind 'emitter_on'",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_a_bad_description_fails_on_one_line_naming_the_field(case, tmp_path, variant):
    (old, new), message = BAD[case]
    text = TABLE.read_text().replace('scene = "table.xml"', f'scene = "{XML}"')
    assert old in text
    task = _write(tmp_path, text.replace(old, new))
    out = tmp_path / "out"
    res = CliRunner().invoke(main, ["render", str(task), "--frames", "4", "--out", str(out)])
    assert res.exit_code == 2, res.output
    (line,) = res.output.strip().splitlines()
    assert re.search(message, line), line
    assert line.startswith(f"Error: {task}: ")  # the description file first
    assert not out.exists()  # nothing written


def test_a_missing_scene_file_is_named(tmp_path):
    task = _write(tmp_path, TABLE.read_text().replace("table.xml", "nosuch.xml"))
    with pytest.raises(ConfigError, match=r"scene = '.*/nosuch.xml': cannot read it"):
        load_family(task, seed=0, num_frames=2)


def test_an_edited_scene_file_is_another_dataset(tmp_path, variant):
    xml = _write(tmp_path, XML.read_text(), "table.xml")
    task = _write(tmp_path, TABLE.read_text())
    fam = load_family(task, seed=0, num_frames=2)
    pinned = {"scene_sha256": fam.config.scene_sha256}
    xml.write_text(xml.read_text().replace('value="0.35"', 'value="0.36"'))
    with pytest.raises(ConfigError, match=r"scene_sha256 = '[0-9a-f]+': the scene file now has"):
        load_family(task, seed=0, num_frames=2, overrides=pinned)
    assert load_family(task, seed=0, num_frames=2).config.scene_sha256 != pinned["scene_sha256"]
