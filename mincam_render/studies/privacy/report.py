"""The privacy report: ``privacy.json`` (numbers), ``privacy.html`` (tables, figures), a PNG.

:func:`write_report` takes the :class:`~.result.PrivacyResult` of
:func:`~.study.run` and the examples it wrote beside it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from mincam_render.studies.privacy.figures import (
    curve_figure,
    examples_figure,
    foreground_figure,
)
from mincam_render.studies.privacy.metrics import FOREGROUND_SPECK_PX, FOREGROUND_THRESHOLD
from mincam_render.studies.privacy.result import DecoderChoice, PrivacyResult

if TYPE_CHECKING:
    from mincam_render.analysis.report import Report
    from mincam_render.analysis.statistics import Interval


def _iv(x: Interval, digits: int = 3) -> str:
    return f"{x.mean:.{digits}f} [{x.low:.{digits}f}, {x.high:.{digits}f}]"


def headline(privacy: PrivacyResult) -> str:
    """One line: how many minimalist designs sit in the corner against a task-matched baseline."""
    corner = privacy.corner
    inside = [n for n, c in corner.items() if c.in_corner_against]
    if not inside:
        return (
            f"no minimalist design is in the corner: none beats a task-matched baseline on both "
            f"attacks with separated 95 % intervals ({len(corner)} designs audited)"
        )
    return f"in the corner (private and as useful as a baseline): {', '.join(inside)}"


#: Columns of :func:`design_rows` after the design's name, pixels and task error.
DESIGN_COLUMNS = (
    "task training",
    "people PSNR (dB)",
    "gain over trivial (dB, paired)",
    "gain over prior (dB, paired)",
    "people SSIM",
    "view PSNR (dB)",
    "view SSIM",
    "re-id top-1",
    "decoder kept",
    "attackers converged",
)

#: The trivial attacker's row label.
TRIVIAL_LABEL = "trivial (background: sees no one; most frequent person)"
#: The prior attacker's row label.
PRIOR_LABEL = "prior (background + where people usually are; read-out ignored)"


def _kept(decoders: Sequence[DecoderChoice]) -> str:
    """Which decoder each attacker seed kept, counted: ``"conv 2, mlp 1"``."""
    kinds = [d.decoder.value for d in decoders]
    return ", ".join(f"{k} {kinds.count(k)}" for k in sorted(set(kinds)))


def design_rows(privacy: PrivacyResult) -> list[list[object]]:
    """Table rows: every design, then the prior, then the trivial attacker and predictor.

    Columns: design, pixels, task error, then :data:`DESIGN_COLUMNS`.
    """
    rows: list[list[object]] = []
    for name, d in privacy.designs.items():
        a, f = d.attack, d.attack.figures
        conv = a.convergence
        attackers = sum(bool(c.decoder["converged"] and c.reid["converged"]) for c in conv)
        rows.append([
            name, d.pixels, _iv(d.task_error), d.task_state, _iv(f.fg_psnr_db, 2),
            _iv(a.fg_psnr_gain_db, 2), _iv(a.fg_psnr_over_prior_db, 2), _iv(f.fg_ssim),
            _iv(f.psnr_db, 2), _iv(f.ssim), _iv(f.figure("reid_top1")), _kept(a.decoders),
            f"{attackers} of {len(conv)}",
        ])  # fmt: skip
    t, p = privacy.trivial, privacy.prior
    pf, tf = p.figures, t.figures
    rows.append([
        PRIOR_LABEL, 0, "", "", _iv(pf.fg_psnr_db, 2), _iv(p.fg_psnr_gain_db, 2), "0",
        _iv(pf.fg_ssim), _iv(pf.psnr_db, 2), _iv(pf.ssim), "", "", "",
    ])  # fmt: skip
    rows.append([
        TRIVIAL_LABEL, 0, _iv(t.task_error), "", _iv(tf.fg_psnr_db, 2), "0", "",
        _iv(tf.fg_ssim), _iv(tf.psnr_db, 2), _iv(tf.ssim), _iv(tf.figure("reid_top1")), "", "",
    ])  # fmt: skip
    return rows


def decoder_rows(privacy: PrivacyResult) -> tuple[list[str], list[list[object]]]:
    """``(header, rows)``: every decoder's people PSNR per design, whichever the attacker kept."""
    designs = privacy.designs
    kinds = list(next(iter(designs.values())).attack.by_decoder) if designs else []
    header = ["design", *(f"{k.value}: people PSNR (dB)" for k in kinds)]
    rows: list[list[object]] = [
        [name, *(_iv(d.attack.by_decoder[k].fg_psnr_db, 2) for k in kinds)]
        for name, d in designs.items()
    ]
    return header, rows


#: Header of :func:`paired_rows`.
PAIRED_HEADER = ["design", "task-matched baseline", "people PSNR (dB)", "re-id top-1"]


def paired_rows(privacy: PrivacyResult) -> list[list[object]]:
    """Per minimalist design and task-matched baseline: attack figures design − baseline, paired."""
    return [
        [name, base, _iv(diff["fg_psnr_db"], 2), _iv(diff["reid_top1"])]
        for name, c in privacy.corner.items()
        for base, diff in c.paired.items()
    ]


def _tables(page: Report, privacy: PrivacyResult) -> None:
    page.heading("Every design")
    page.table(
        ["design", "pixels", f"task {privacy.error_name}", *DESIGN_COLUMNS],
        design_rows(privacy),
        caption="Mean [95 % CI]. Task: over training seeds and test episodes; attacks: over "
        "attacker seeds and test episodes. People: PSNR and SSIM on the foreground (the pixels "
        "the people change); view: the whole image. The attacker is given each frame's "
        "background (the empty room): the trivial row sees no one; the prior adds where people "
        "usually are in the training views, still without the read-out. The gains are the people "
        "PSNR minus the trivial or the prior attacker's, paired on the test episodes: a gain "
        "over the prior whose interval excludes 0 is what the read-out tells about the people.",
    )
    page.heading("Verdicts (only where intervals separate)")
    page.bullets([c.verdict for c in privacy.corner.values()])
    page.table(
        PAIRED_HEADER,
        paired_rows(privacy),
        caption="Design minus baseline on the same test episodes (mean [95 % CI]); below 0 on "
        "both attacks: more private on these episodes. Reported beside the verdict, not as it.",
    )
    page.heading("Every decoder")
    page.table(
        *decoder_rows(privacy),
        caption="People PSNR of each decoder the attacker trained (mean [95 % CI] over attacker "
        "seeds and test episodes); the table above keeps, per seed, the one of the lowest "
        "validation error.",
    )


def _method(page: Report, privacy: PrivacyResult) -> None:
    cfg = privacy.config
    cmp, att = cfg["comparison"], cfg["attack"]
    page.heading("Method")
    page.bullets([
        f"Scene: {privacy.task} at {cmp['fps']:g} fps with a roster of {privacy.roster} "
        f"people (fixed looks and gait; overrides {cmp['overrides']}); "
        f"{cmp['train_episodes']} training episodes of {cmp['train_frames']} frames, one "
        f"validation episode, {cmp['test_episodes']} test episodes of {cmp['test_frames']}.",
        f"Render: {cmp['fidelity']} (fixed, cheap; every design sees the same transport).",
        f"Attacker: knows the design and each frame's background (the same frame rendered "
        f"with its people removed), trains on the training episodes (never the test ones) "
        f"decoders of what the people add to the {att['view_width']} x {att['view_width']} "
        "view (display image, gamma 2.2): an MLP, a convolutional decoder and a ridge "
        "regression, keeping whichever reconstructs the validation episode best, and an MLP "
        f"re-identifier; {att['seeds']} seeds, networks of at most {att['max_steps']} steps, "
        "the best validation state kept.",
        "Foreground: pixels whose display value differs from the background by more than "
        f"{FOREGROUND_THRESHOLD:g}, specks of at most {FOREGROUND_SPECK_PX} pixels dropped "
        f"({100 * privacy.trivial.fg_fraction:.1f} % of the test "
        "pixels). PSNR and SSIM: scikit-image, per frame, averaged (SSIM's map averaged over "
        "the foreground); re-id: the top-scored person is in the room, over frames with "
        "someone inside.",
    ])  # fmt: skip


def write_report(
    privacy: PrivacyResult,
    out_dir: str | Path,
    examples: Mapping[str, np.ndarray] | None = None,
) -> dict[str, str]:
    """Write ``privacy.json``, ``privacy.html`` and ``privacy.png`` (the curve) to ``out_dir``.

    Args:
        privacy: the audit's result (:func:`~.study.run`).
        out_dir: created if needed.
        examples: the reconstructions shown (``examples.npz``'s arrays); None
            reads ``out_dir/examples.npz``, which :func:`~.study.run` wrote.

    Returns:
        ``{"json": path, "html": path, "png": path}``.
    """
    from mincam_render.analysis.report import Report, figure_png
    from mincam_render.data.dataset import atomic_write_bytes, json_bytes

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if examples is None:
        with np.load(out / "examples.npz") as saved:
            examples = dict(saved)
    page = Report("Privacy audit: what can an attacker recover from K measurements?")
    page.heading("Answer")
    page.paragraph(headline(privacy))
    page.figure(*curve_figure(privacy))
    _tables(page, privacy)
    page.figure(*examples_figure(privacy, examples))
    page.figure(*foreground_figure(privacy, examples))
    _method(page, privacy)
    png = atomic_write_bytes(out / "privacy.png", figure_png(curve_figure(privacy)[0]))
    json_path = atomic_write_bytes(out / "privacy.json", json_bytes(privacy.as_json()))
    html_path = page.write(out / "privacy.html")
    return {"json": str(json_path), "html": str(html_path), "png": str(png)}
