"""Figures the README and the docs quote equal the results files they come from.

A figure typed into prose drifts when its study is run again; these tests read
the JSON a sentence names and look for the same figure, rounded as quoted, in
the text. Each case is a figure a newcomer reads first.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
MAIN_JOB_MASKS = REPO / "masks" / "workspace" / "main-job-mincam-8px"
DESIGN_PROTOCOL = REPO / "benchmarks" / "results" / "design_protocol.json"


def _interval(error: dict) -> str:
    """``mean [lo, hi]`` at three decimals, as the docs quote a figure."""
    lo, hi = error["ci95"]
    return f"{error['mean']:.3f} [{lo:.3f}, {hi:.3f}]"


def _read(path: Path) -> str:
    return path.read_text(encoding="utf-8")


@pytest.mark.parametrize("doc", ["README.md", "masks/README.md"])
def test_the_main_jobs_kept_people_count_figure_is_its_sidecars(doc):
    sidecar = json.loads(_read(MAIN_JOB_MASKS / "people_count" / "masks.json"))
    figure = _interval(sidecar["provenance"]["test_error_over_seeds"])
    assert figure in _read(REPO / doc), f"{doc} does not quote the kept masks' {figure}"


def test_the_readme_shows_the_kept_print_sheet_and_the_learning_curves():
    readme = _read(REPO / "README.md")
    for target in (
        "masks/workspace/main-job-mincam-8px/people_count/print_sheet.svg",
        "benchmarks/results/design_protocol_workspace.png",
    ):
        assert target in readme and (REPO / target).is_file(), target


def test_the_design_protocols_learning_curve_at_its_largest_size_is_the_jsons():
    ladder = json.loads(_read(DESIGN_PROTOCOL))["workspace"]["ladder"][-1]
    doc = _read(REPO / "docs" / "design_protocol.md")
    row = next(ln for ln in doc.splitlines() if ln.startswith(f"| {ladder['episodes']} |"))
    for name in ("mincam-2px", "mincam-8px", "baseline-8x8", "baseline-32x32"):
        d = ladder["designs"][name]
        quoted = _interval({"mean": d["error"], "ci95": d["ci95"]})
        assert quoted in row, f"docs/design_protocol.md: {name} at {ladder['episodes']} episodes"
    assert f"| {round(ladder['render_s'])} |" in row


#: The floor tables' row marker of entries trained on episodes rendered at a multiple of the plan.
TRAINED_AT = {"workspace-4x": ", trained at 4x |"}


@pytest.mark.parametrize("entry", ["workspace-10test", "workspace-4x", "lighting"])
def test_the_design_protocols_floors_are_the_jsons(entry):
    floors = json.loads(_read(DESIGN_PROTOCOL))[entry]["floors"]
    doc = _read(REPO / "docs" / "design_protocol.md")
    assert floors, f"{entry} has no floors"
    for check in floors:
        (lo, hi), mean = check["paired"]["ci95"], check["paired"]["mean"]
        quoted = f"{mean:+.3f} [{lo:+.3f}, {hi:+.3f}] | {check['verdict']} |"
        name = f"{check['floor']['design']} − {check['floor']['baseline']}"
        factor = check.get("test_factor", 1.0)  # on re-rendered tests: its own row
        rows = [ln for ln in doc.splitlines() if ln.startswith(f"| {name} <")]
        rows = [ln for ln in rows if (f"| {factor:g}x samples |" in ln) == (factor != 1)]
        marker = TRAINED_AT.get(entry)
        rows = [ln for ln in rows if (marker in ln if marker else ", trained at" not in ln)]
        assert rows and quoted in rows[0], f"docs/design_protocol.md: {entry}'s floor {name}"


# ---- every interval a doc quotes is in the results JSON it names -------------------------------

RESULTS = REPO / "benchmarks" / "results"
#: ``mean [lo, hi]`` at three decimals (errors, paired differences) ...
INTERVAL = re.compile(r"([+\-−]?\d+\.\d{3})\s+\[([+\-−]?\d+\.\d{3}),\s+([+\-−]?\d+\.\d{3})\]")
#: ... and ``x.x % [lo, hi]``, a fraction quoted in per cent (increases, accuracies).
PERCENT = re.compile(r"([+\-−]?\d+\.\d) %\s+\[([+\-−]?\d+\.\d),\s+([+\-−]?\d+\.\d)\]")
TRAFFIC_BLOCKS = (
    "traffic's freeform pixels with block masks (block-8, block-4) paired with another recipe "
    "row's design on the same episodes, not stored: recomputed by "
    "test_the_traffic_block_masks_paired_differences"
)
#: Quoted intervals no kept JSON holds, each with where it comes from instead.
NOT_KEPT = {
    "docs/design_protocol.md": dict.fromkeys(
        (
            "−0.028 [−0.135, +0.064]",
            "−0.016 [−0.108, +0.063]",
            "−0.128 [−0.137, −0.119]",
            "+0.059 [+0.037, +0.077]",
            "+0.064 [+0.049, +0.077]",
            "−0.371 [−0.401, −0.348]",
            "−0.159 [−0.174, −0.143]",
            "−0.012 [−0.029, +0.006]",
            "−0.149 [−0.164, −0.135]",
            "−0.006 [−0.019, +0.008]",
        ),
        "paired differences at the ladder's largest size, not stored: recomputed from its "
        "episode errors by test_the_design_protocols_paired_differences_are_its_episode_errors",
    )
    | dict.fromkeys(
        (
            "−0.127 [−0.143, −0.112]",
            "+0.016 [+0.004, +0.029]",
            "−0.079 [−0.091, −0.065]",
            "−0.063 [−0.078, −0.049]",
            "+0.023 [+0.005, +0.039]",
            "+0.027 [+0.014, +0.040]",
            "−0.002 [−0.024, +0.020]",
            "−0.147 [−0.164, −0.129]",
            "−0.073 [−0.086, −0.063]",
            "−0.020 [−0.029, −0.011]",
        ),
        "paired differences at the narrow ladder's 32 episodes, not stored: recomputed by "
        "test_the_design_protocols_paired_differences_are_its_episode_errors",
    )
    | dict.fromkeys(
        (
            "−0.006 [−0.023, +0.013]",
            "−0.013 [−0.024, −0.001]",
            "+0.021 [+0.008, +0.038]",
            "+0.123 [+0.109, +0.135]",
            "−0.059 [−0.084, −0.034]",
            "−0.208 [−0.227, −0.192]",
            "+0.044 [+0.032, +0.060]",
            "−0.038 [−0.051, −0.024]",
            "−0.026 [−0.036, −0.014]",
        ),
        "a freeform design paired with a box camera read through K combinations (two rows "
        "of the recipes table), not stored: recomputed by "
        "test_the_linear_diagnostics_paired_differences_are_their_episode_errors",
    )
    | dict.fromkeys(
        (
            "+0.017 [−0.000, +0.034]",
            "+0.087 [+0.065, +0.109]",
            "+0.007 [−0.005, +0.018]",
            "+0.070 [+0.057, +0.083]",
            "+0.015 [+0.005, +0.025]",
            "+0.064 [+0.047, +0.082]",
            "+0.061 [+0.045, +0.078]",
            "+0.025 [+0.004, +0.045]",
            "−0.018 [−0.029, −0.003]",
            "−0.015 [−0.036, +0.007]",
        ),
        "signed pixels paired with another entry's design on the same episodes (the plain "
        "camera of as many photodiodes, or 32x32 through K combinations), not stored: "
        "recomputed by test_the_signed_pixels_paired_differences_are_their_episode_errors",
    )
    | dict.fromkeys(
        ("+4.162 [+3.144, +5.091]", "+4.079 [+2.994, +5.006]", "+1.974 [+1.418, +2.478]"),
        "paired differences at the traffic ladder's 4 episodes, not stored: recomputed by "
        "test_the_design_protocols_paired_differences_are_its_episode_errors",
    )
    | dict.fromkeys(
        (
            "+0.107 [−0.416, +0.730]",
            "−1.303 [−1.804, −0.865]",
            "−2.107 [−2.632, −1.618]",
            "+0.421 [+0.026, +0.899]",
            "−0.264 [−0.673, +0.077]",
            "−0.158 [−0.598, +0.369]",
            "+0.157 [−0.113, +0.503]",
            "+0.227 [−0.289, +0.900]",
        ),
        TRAFFIC_BLOCKS,
    )
    | dict.fromkeys(
        (
            "−0.391 [−0.870, +0.175]",
            "−0.414 [−0.901, +0.088]",
            "−0.420 [−0.875, +0.067]",
            "+0.048 [−0.506, +0.846]",
        ),
        "paired differences at the largest point of the traffic ladder at 4x (traffic-4x), not "
        "stored: recomputed by test_the_design_protocols_paired_differences_are_its_episode_errors",
    )
    | dict.fromkeys(
        (
            "−0.507 [−1.013, −0.033]",
            "−0.529 [−0.877, −0.157]",
            "−0.535 [−0.874, −0.176]",
            "+0.119 [−0.404, +0.742]",
            "−0.810 [−1.238, −0.400]",
            "−0.919 [−1.372, −0.411]",
            "−0.410 [−1.054, +0.177]",
            "−0.048 [−0.260, +0.169]",
            "−0.590 [−1.014, −0.088]",
            "−0.613 [−1.117, −0.174]",
            "−0.619 [−1.081, −0.192]",
            "−0.083 [−0.328, +0.165]",
            "+0.157 [−0.150, +0.538]",
            "−0.199 [−0.528, +0.074]",
        ),
        "traffic's PCA-tuned masks (traffic-4x-references) paired with the traffic-4x ladder's "
        "designs on the same episodes, two entries: recomputed by "
        "test_the_traffic_references_paired_with_the_ladders_designs",
    )
    | dict.fromkeys(
        ("1.407 [1.386, 1.425]", "1.399 [1.375, 1.420]"),
        "the patches mask learning-rate diagnostic (mincam 8 px alone, mask_lr 0.01 and 0.2, "
        "on the ladder's 16 episodes, 2026-12-06); a comparison run outside the bench, not kept",
    ),
    "docs/fidelity.md": dict.fromkeys(
        ("−0.008 [−0.070, +0.047]", "−0.042 [−0.098, +0.010]"),
        "4x runs on 16 episodes less the plan's runs on 32, on the same 4x test renders: "
        "`workspace-16`'s 4x designs paired with `workspace-32`'s 1x-on-4x cross (Paired.of "
        "on their episode errors in task_fidelity.json); two entries, not one stored pair",
    ),
    "docs/lighting_and_traffic.md": dict.fromkeys(
        (
            "0.105 [0.093, 0.115]",
            "0.049 [0.037, 0.064]",
            "0.088 [0.073, 0.099]",
            "0.029 [0.020, 0.041]",
            "0.059 [0.040, 0.074]",
        ),
        "`pipeline` runs at 367fc4b and 8cfc910 on the robustness episodes; not kept",
    ),
    "docs/studies.md": dict.fromkeys(
        (
            "1.043 [0.926, 1.196]",
            "1.013 [0.887, 1.113]",
            "1.833 [0.953, 2.237]",
            "+0.030 [-0.167, +0.260]",
            "-0.790 [-1.141, -0.045]",
            "0.968 [0.875, 1.070]",
            "1.112 [0.914, 1.236]",
            "2.137 [1.187, 2.701]",
            "-0.144 [-0.322, +0.090]",
            "-1.169 [-1.694, -0.197]",
            "0.940 [0.688, 1.243]",
            "0.986 [0.705, 1.293]",
            "0.991 [0.545, 1.404]",
            "-0.046 [-0.125, +0.046]",
            "-0.050 [-0.152, +0.144]",
        ),
        "the main job run from a fresh clone at c8ce75e with root seeds 0, 1, 2; not kept",
    )
    | dict.fromkeys(("−0.158 [−0.598, +0.369]",), TRAFFIC_BLOCKS)
    | dict.fromkeys(
        ("−0.507 [−1.013, −0.033]", "−0.535 [−0.874, −0.176]"),
        "traffic's PCA-tuned masks paired with the traffic-4x ladder's box cameras: "
        "recomputed by test_the_traffic_references_paired_with_the_ladders_designs",
    ),
}
#: Docs that must stay covered (a renamed results file would otherwise drop one silently).
COVERED = {
    "docs/benchmarks.md", "docs/design_protocol.md", "docs/energy.md", "docs/fidelity.md",
    "docs/lighting_and_traffic.md", "docs/privacy.md", "docs/robustness.md", "docs/studies.md",
}  # fmt: skip


def _number(text: str) -> float:
    return float(text.replace("−", "-"))


def _results_intervals(node, found: set[tuple[float, float, float]]) -> set:
    """Every ``(figure, lo, hi)`` of a results JSON, in the shapes the results use.

    ``{"mean" | "error": m, "ci95": [lo, hi]}`` (``Interval.as_dict``, the design
    ladder), ``{"X" | "X_mean": m, "X_ci95": [lo, hi]}`` (studies, ablation),
    ``{"mean_X": m, "ci95_X": [lo, hi]}`` (robustness) and ``[m, [lo, hi]]``
    (the design protocol's figures).
    """
    if isinstance(node, dict):
        for key, value in node.items():
            pair = isinstance(value, list) and len(value) == 2
            if pair and all(isinstance(v, int | float) for v in value) and "ci95" in key:
                name = key.replace("ci95", "").strip("_")
                names = (name, f"{name}_mean", f"mean_{name}") if name else ("mean", "error")
                for n in names:
                    if isinstance(node.get(n), int | float):
                        found.add((node[n], *value))
            _results_intervals(value, found)
    elif isinstance(node, list):
        if len(node) == 2 and isinstance(node[0], int | float) and isinstance(node[1], list):
            if len(node[1]) == 2 and all(isinstance(v, int | float) for v in node[1]):
                found.add((node[0], *node[1]))
        for value in node:
            _results_intervals(value, found)
    return found


def _named_results(text: str) -> list[Path]:
    """The results JSONs a doc names: ``X.json``, ``X.md``, ``X.png``, ``X.{json,...}``.

    Or a study's bare name in backticks (`` `study_workspace_16px` ``); a bare
    word (`` `render` ``) is a command, not a results file.
    """
    stems = set(re.findall(r"(?<![\w-])([a-z0-9_]+)(?:\.json|\.md|\.png|\.\{json)", text))
    stems |= set(re.findall(r"`([a-z0-9]+_[a-z0-9_]+)`", text))
    return sorted(p for p in RESULTS.rglob("*.json") if p.stem in stems)


def _docs_naming_results() -> list[str]:
    docs = sorted((REPO / "docs").glob("*.md"))
    return [str(p.relative_to(REPO)) for p in docs if _named_results(_read(p))]


def test_the_docs_that_quote_kept_results_are_all_checked():
    assert COVERED <= set(_docs_naming_results())


@pytest.mark.parametrize("doc", _docs_naming_results())
def test_every_interval_a_doc_quotes_is_in_the_results_it_names(doc):
    text = _read(REPO / doc)
    kept: set = set()
    for path in _named_results(text):
        kept |= _results_intervals(json.loads(_read(path)), set())
    decimals = {tuple(f"{v:.3f}" for v in t) for t in kept}
    percents = {tuple(f"{100 * v:.1f}" for v in t) for t in kept}
    wrong = []
    for pattern, known, fmt in ((INTERVAL, decimals, "{:.3f}"), (PERCENT, percents, "{:.1f}")):
        for m in pattern.finditer(text):
            quoted = " ".join(m.group(0).split())
            figure = tuple(fmt.format(_number(g)) for g in m.groups())
            if figure not in known and quoted not in NOT_KEPT.get(doc, {}):
                wrong.append(f"line {text.count(chr(10), 0, m.start()) + 1}: {quoted}")
    names = [p.name for p in _named_results(text)]
    assert not wrong, f"{doc} quotes intervals none of {names} holds: {wrong}"


@pytest.mark.parametrize(
    ("entry", "a", "b", "quoted"),
    [
        ("workspace", "mincam-2px", "baseline-8x8", "mincam 2 px − 8×8"),
        ("workspace", "mincam-8px", "baseline-32x32", "mincam 8 px − 32×32"),
        ("patches", "mincam-2px", "baseline-2x2", "mincam 2 px − 2×2"),
        ("patches", "mincam-8px", "baseline-8x8", "mincam 8 px − 8×8"),
        ("patches", "mincam-8px", "baseline-32x32", "− 32×32"),
        ("patches-narrow", "mincam-2px", "baseline-2x2", "mincam 2 px − 2×2"),
        ("patches-narrow", "mincam-8px", "baseline-8x8", "mincam 8 px − 8×8"),
        ("patches-narrow", "mincam-8px", "baseline-32x32", "− 32×32"),
        ("patches-narrow-16", "mincam-8px", "baseline-8x8", "mincam 8 px − 8×8"),
        ("patches-narrow-16", "mincam-2px", "baseline-8x8", "mincam 2 px − 8×8"),
        ("patches-narrow-32", "mincam-8px", "baseline-8x8", "mincam 8 px − 8×8"),
        ("patches-narrow-32", "mincam-2px", "baseline-8x8", "mincam 2 px − 8×8"),
        ("patches-narrow-pixels", "mincam-4px", "mincam-2px", "mincam 4 px − 2 px"),
        ("patches-narrow-pixels", "mincam-4px", "baseline-8x8", "mincam 4 px − 8×8"),
        ("patches-pixels", "mincam-16px", "baseline-32x32", "mincam 16 px − 32×32"),
        ("patches-pixels", "mincam-16px", "baseline-8x8", "mincam 16 px − 8×8"),
        ("patches-pixels", "mincam-16px", "mincam-8px", "16 px − 8 px"),
        ("patches-narrow-pixels", "mincam-16px", "mincam-8px", "16 px − 8 px"),
        ("patches-narrow-pixels", "mincam-16px", "baseline-32x32", "mincam 16 px − 32×32"),
        ("patches-narrow-pixels", "mincam-16px", "baseline-8x8", "mincam 16 px − 8×8"),
        ("traffic", "mincam-8px", "baseline-2x4", "mincam 8 px − 2×4"),
        ("traffic", "mincam-2px", "baseline-2x4", "mincam 2 px − 2×4"),
        ("traffic", "mincam-8px", "baseline-16x28", "mincam 8 px − 16×28"),
        ("traffic-4x", "mincam-8px", "baseline-2x4", "mincam 8 px − 2×4"),
        ("traffic-4x", "mincam-8px", "baseline-8x14", "mincam 8 px − 8×14"),
        ("traffic-4x", "mincam-8px", "baseline-16x28", "mincam 8 px − 16×28"),
        ("traffic-4x", "mincam-2px", "baseline-2x4", "mincam 2 px − 2×4"),
    ],
)
def test_the_design_protocols_paired_differences_are_its_episode_errors(entry, a, b, quoted):
    ladder = json.loads(_read(DESIGN_PROTOCOL))[entry]["ladder"][-1]
    figure = _paired(ladder["designs"][a], ladder["designs"][b])
    assert f"{quoted} {figure}".replace("−", "-") in _protocol_doc(), (entry, a, b, figure)


#: Designs of the traffic entries at 4x: ``(where, k, design)``, ``k`` the pixels of a
#: references row or the training episodes of a ladder point.
PCA_TUNED_8 = ("references", 8, "mincam-8px-pca-tuned")
PCA_TUNED_8_AT_4 = ("references-4", 8, "mincam-8px-pca-tuned")
CHOSEN_8 = ("restarts", 8, "mincam-8px")


def _boxes(episodes: int) -> list[tuple[str, int, str]]:
    """The box cameras of the ``traffic-4x`` ladder's point of ``episodes``."""
    return [("ladder", episodes, f"baseline-{g}") for g in ("2x4", "8x14", "16x28")]


@pytest.mark.parametrize(
    ("a", "b", "quoted"),
    [
        *zip([PCA_TUNED_8] * 3, _boxes(8), ["tuned − 2×4", "− 8×14", "− 16×28"], strict=True),
        *zip([PCA_TUNED_8_AT_4] * 3, _boxes(4), ["− 2×4", "− 8×14", "− 16×28"], strict=True),
        *zip([CHOSEN_8] * 3, _boxes(8), ["chosen − 2×4", "− 8×14", "− 16×28"], strict=True),
        (("references", 2, "mincam-2px-pca-tuned"), _boxes(8)[0], "tuned − 2×4"),
        (PCA_TUNED_8, PCA_TUNED_8_AT_4, "8 − 4"),
        (CHOSEN_8, PCA_TUNED_8, "chosen − PCA-tuned"),
        (("restarts", 2, "mincam-2px"), ("restarts-plain", 2, "mincam-2px"), "0.068) |"),
        (CHOSEN_8, ("restarts-plain", 8, "mincam-8px"), "0.092) |"),
    ],
)
def test_the_traffic_references_paired_with_the_ladders_designs(a, b, quoted):
    """A design of ``traffic-4x-references`` (8 training episodes), ``-references-4`` (4) or
    ``-restarts`` (the chosen runs) against another entry's on the same test episodes: the
    ``traffic-4x`` ladder's point of ``k`` episodes, or a reference."""
    results = json.loads(_read(DESIGN_PROTOCOL))

    def design(where: str, k: int, name: str) -> dict:
        """The record of ``name``'s episode errors (restarts: the chosen or the plain runs')."""
        if where == "ladder":
            return {p["episodes"]: p for p in results["traffic-4x"]["ladder"]}[k]["designs"][name]
        if where.startswith("restarts"):
            rows = {r["design"]: r for r in results["traffic-4x-restarts"]["restarts"]}
            return rows[name]["plain" if where.endswith("-plain") else "chosen"]
        rows = results[f"traffic-4x-{where}"]["references"]
        return {r["pixels"]: r for r in rows}[k]["designs"][name]

    figure = _paired(design(*a), design(*b))
    assert f"{quoted} {figure}".replace("−", "-") in _protocol_doc(), (a, b, figure)
    if a == PCA_TUNED_8 and b[::2] in (
        ("ladder", "baseline-2x4"),
        ("ladder", "baseline-16x28"),
    ):
        grid = b[2].removeprefix("baseline-")
        assert f"{grid} {figure}" in _plain_doc("studies.md"), (a, b, figure)


def _paired(a: dict, b: dict) -> str:
    """``a - b`` of two designs' records on the same episodes, as the docs quote it."""
    from mincam_render.analysis.statistics import EpisodeErrors, paired_difference

    diff = paired_difference(*(EpisodeErrors.from_dict(d["episode_errors"]) for d in (a, b)))
    return f"{diff.mean:+.3f} [{diff.low:+.3f}, {diff.high:+.3f}]"


def _plain_doc(name: str) -> str:
    """``docs/<name>`` with plain minus signs and single spaces."""
    return " ".join(_read(REPO / "docs" / name).replace("−", "-").split())


def _protocol_doc() -> str:
    return _plain_doc("design_protocol.md")


def _recipe_rows(results: dict, entry: str) -> dict[str, dict]:
    """``{variant: row}`` of a design-protocol entry's recipes table."""
    return {r["variant"]: r for r in results[entry]["recipes"]}


@pytest.mark.parametrize(
    ("entry", "a", "variant", "b"),
    [
        ("patches-linear", "mincam-8px", "linear-8", "baseline-32x32"),
        ("patches-narrow-linear", "mincam-8px", "linear-8", "baseline-32x32"),
        ("patches-linear", "mincam-2px", "linear-2", "baseline-32x32"),
        ("patches-narrow-linear", "mincam-2px", "linear-2", "baseline-32x32"),
        ("patches-linear", "mincam-8px", "linear-8", "baseline-8x8"),
        ("patches-narrow-linear", "mincam-8px", "linear-8", "baseline-8x8"),
        ("patches-narrow-pixels", "mincam-4px", "linear-2", "baseline-32x32"),
        ("patches-pixels", "mincam-16px", "linear-16", "baseline-32x32"),
        ("patches-narrow-pixels", "mincam-16px", "linear-16", "baseline-32x32"),
    ],
)
def test_the_linear_diagnostics_paired_differences_are_their_episode_errors(entry, a, variant, b):
    """``a`` at the entry's largest ladder point (or its base recipe) against ``b`` read
    through ``variant`` on the same episodes (the wide or narrow ``*-linear`` entry)."""
    results = json.loads(_read(DESIGN_PROTOCOL))
    linear = "patches-narrow-linear" if "narrow" in entry else "patches-linear"
    rows = _recipe_rows(results, linear)
    first = results[entry]["ladder"][-1] if results[entry]["ladder"] else rows["base"]
    figure = _paired(first["designs"][a], rows[variant]["designs"][b])
    assert figure in _protocol_doc(), (entry, a, variant, b, figure)


@pytest.mark.parametrize(
    ("entry", "k", "other", "b"),
    [
        ("patches-signed", 2, "patches-pixels", "mincam-4px"),
        ("patches-signed", 4, "patches-pixels", "mincam-8px"),
        ("patches-signed", 8, "patches-pixels", "mincam-16px"),
        ("patches-narrow-signed", 2, "patches-narrow-pixels", "mincam-4px"),
        ("patches-narrow-signed", 4, "patches-narrow-pixels", "mincam-8px"),
        ("patches-narrow-signed", 8, "patches-narrow-pixels", "mincam-16px"),
        ("patches-signed", 2, "patches-linear", "baseline-32x32"),
        ("patches-narrow-signed", 2, "patches-narrow-linear", "baseline-32x32"),
        ("patches-signed", 8, "patches-linear", "baseline-32x32"),
        ("patches-narrow-signed", 8, "patches-narrow-linear", "baseline-32x32"),
    ],
)
def test_the_signed_pixels_paired_differences_are_their_episode_errors(entry, k, other, b):
    """``k`` signed pixels against ``b`` of another entry on the same episodes: the
    unsigned camera of as many photodiodes (its ladder point), or 32x32 read through
    ``k`` signed combinations (the ``*-linear`` entry's ``linear-k``)."""
    results = json.loads(_read(DESIGN_PROTOCOL))
    signed = _recipe_rows(results, entry)["signed"]
    if other.endswith("-linear"):
        against = _recipe_rows(results, other)[f"linear-{k}"]["designs"][b]
    else:
        against = results[other]["ladder"][-1]["designs"][b]
    figure = _paired(signed["designs"][f"mincam-{k}px"], against)
    assert figure in _protocol_doc(), (entry, k, other, b, figure)


@pytest.mark.parametrize(
    ("entry", "design", "block", "variant", "b", "quoted"),
    [
        ("traffic-recipes", "mincam-8px", "block-8", "base", "baseline-2x4", "− 2×4 (base)"),
        ("traffic-recipes", "mincam-8px", "block-8", "base", "baseline-8x14", "− 8×14"),
        ("traffic-recipes", "mincam-8px", "block-8", "base", "baseline-16x28", "− 16×28"),
        ("traffic-recipes", "mincam-8px", "block-8", "gain-20", "baseline-2x4", "− 2×4 (gain-20)"),
        ("traffic-recipes", "mincam-8px", "block-4", "base", "baseline-2x4", "− 2×4 (base)"),
        ("traffic-recipes", "mincam-8px", "block-4", "gain-20", "baseline-2x4", "− 2×4 (gain-20)"),
        ("traffic-recipes", "mincam-8px", "block-4", "block-8", "mincam-8px", "− block-8"),
        ("traffic-4x", "mincam-2px", "block-4", "base", "baseline-2x4", "block-4 − 2×4"),
    ],
)
def test_the_traffic_block_masks_paired_differences(entry, design, block, variant, b, quoted):
    """Traffic's freeform design with block masks against a design of another recipe row."""
    rows = _recipe_rows(json.loads(_read(DESIGN_PROTOCOL)), entry)
    figure = _paired(rows[block]["designs"][design], rows[variant]["designs"][b])
    assert f"{quoted} {figure}".replace("−", "-") in _protocol_doc(), (block, variant, b, figure)
    if (entry, block, variant, b) == ("traffic-recipes", "block-4", "base", "baseline-2x4"):
        assert f"2x4 ({figure})" in _plain_doc("studies.md"), figure


# ---- the self-powered budget: energy.json's headline figures, as docs quote them ---------------


def _energy_quotes() -> dict[str, list[str]]:
    """``{doc: [figure as quoted]}`` of ``benchmarks/results/energy.json``."""
    energy = json.loads(_read(RESULTS / "energy.json"))
    t = energy["result"]["threshold"]  # the 24-pixel, 30 fps budget
    fams = energy["result"]["families"]
    ws, li = fams["workspace"], fams["lighting"]
    peak = {k: max(v) for k, v in li["sustainable_fps"].items()}
    at_30 = max(int(k) for k, v in peak.items() if v >= 30.0)
    depth = {(r["depth"], r["component"]): r for r in energy["depth_check"]["rows"]}
    low = sorted(-100 * r["relative_to_deepest"] for (d, _), r in depth.items() if d == 3)
    at_12 = max(-100 * r["relative_to_deepest"] for (d, _), r in depth.items() if d == 12)
    depth_figures = [f"reads {low[0]:.0f}–{low[-1]:.0f} % low", f"within {at_12:.2f} %"]
    mc = [100 * f["render"]["max_relative_error_total"] for f in (ws, li)]
    cmp = energy["result"]["comparisons"]

    def power(c: dict) -> str:
        mincam, module = (1e3 * c[k]["power_at_fps_w"] for k in ("mincam", "module"))
        return f"{mincam:.2f} vs {module:.1f} mW"

    benchmarks = [
        f"**{1e3 * t['power_at_fps_w']:.2f} mW**",
        f"{1e6 * t['energy_per_frame_j']:.1f} µJ a frame",
        f"{1e6 * t['static_w']:.1f} µW static",
        f"**{t['threshold_lux']:.0f} lx**",
        f"peaks at {max(ws['lux']):.0f} lx",
        f"**{ws['hours_at_fps']['24']:.1f} h**",
        f"(1 px: {ws['hours_at_fps']['1']:.1f} h)",
        f"{max(li['lux']):.0f} lx, enough for 30 fps up to {at_30}",
        f"sustain {peak['24']:.1f} fps and run {li['hours_at_fps']['24']:.1f} h",
        *(power(cmp[f]) for f in ("workspace", "lighting", "patches")),
        *depth_figures,
        f"{max(mc):.2f} %",
    ]
    energy_md = [
        *depth_figures,
        f"it is {mc[0]:.2f} % (workspace) and {mc[1]:.2f} % (lighting)",
        f"a 24-pixel frame costs {1e6 * t['energy_per_frame_j']:.1f} µJ",
        f"({1e6 * t['radio_j']:.1f} µJ), {1e6 * t['compute_j']:.1f} µJ the head",
        f"{1e6 * t['readout_j']:.1f} µJ the",  # readout (the line breaks after "the")
        f"static draw is {1e6 * t['static_w']:.1f} µW",
    ]
    for kind, quoted, fmt in (("light=", "a ceiling bank alone", "{:.4f}"),
                              ("daylight", "the noon daylight", "{:.3f}")):  # fmt: skip
        rows = sorted((d, r) for (d, comp), r in depth.items() if comp.startswith(kind))
        levels = " / ".join(fmt.format(r["irradiance_w_m2"]) for _, r in rows)
        energy_md.append(f"{quoted} {levels} W/m²")
    weakest = 100 * max(f["render"]["max_relative_error_component"] for f in (ws, li))
    energy_md.append(f"(a floor lamp alone, early twilight) reach {weakest:.1f} %")
    return {"docs/benchmarks.md": benchmarks, "docs/energy.md": energy_md}


@pytest.mark.parametrize("doc", ["docs/benchmarks.md", "docs/energy.md"])
def test_the_self_powered_budgets_figures_are_energy_jsons(doc):
    text = " ".join(_read(REPO / doc).split())
    missing = [q for q in _energy_quotes()[doc] if q not in text]
    assert not missing, f"{doc} does not quote energy.json's {missing}"
