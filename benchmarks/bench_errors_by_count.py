r"""Where a count's test errors lie: bias and RMSE at each true count, per design.

Usage::

    python benchmarks/bench_errors_by_count.py --key workspace-32 \
        --runs /work/protocol-ws10/ladder/episodes-32/runs/people_count \
        --episodes /work/episodes/ws8 --train-episodes 32 --test-episodes 10 \
        --label people_count

Reads the kept runs of a comparison (``RUNS/<design>-seed<i>``; nothing is
trained), predicts every test episode (``EPISODES/test-<i>``) with every seed,
post-processes as the headline figure does (rounded, median filtered) and splits
the errors by the true count (:mod:`mincam_render.analysis.errors_by_count`):
bias with its 95 % interval over seeds and test episodes, RMSE, and each count's
share of the test frames and of the training frames
(``EPISODES/train-<i>``, labels only). The trivial predictor (the training
mean, post-processed alike) is shown beside the designs.

Merges the entry ``KEY`` into ``benchmarks/results/errors_by_count.json`` and
writes ``errors_by_count_<key>.md`` and ``.png`` (bias against true count).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path
from typing import Any

import numpy as np
from provenance import machine, write_result

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mincam_render.analysis.errors_by_count import CountBin, errors_by_count  # noqa: E402
from mincam_render.analysis.plots import plt  # noqa: E402
from mincam_render.data.dataset import open_dataset  # noqa: E402
from mincam_render.learn.evaluation import postprocess, predict  # noqa: E402
from mincam_render.learn.restore import open_run, restore_model  # noqa: E402
from mincam_render.learn.train import TrainingData  # noqa: E402

RESULTS = Path(__file__).parent / "results"
RUN_NAME = re.compile(r"(?P<design>.+)-seed(?P<seed>\d+)$")


def design_runs(runs: Path) -> dict[str, list[Path]]:
    """``{design: [run directory per seed, in seed order]}`` under ``runs``."""
    found: dict[str, dict[int, Path]] = {}
    for path in sorted(runs.iterdir()):
        m = RUN_NAME.match(path.name)
        if m and path.is_dir():
            found.setdefault(m["design"], {})[int(m["seed"])] = path
    if not found:
        raise FileNotFoundError(f"{runs}: no <design>-seed<i> runs")
    return {d: [seeds[s] for s in sorted(seeds)] for d, seeds in found.items()}


def predictions(runs: list[Path], tests: list[TrainingData], label: str) -> np.ndarray:
    """``[seed, frame]`` post-processed predictions of ``label``, test episodes in order."""
    out = []
    for path in runs:
        # one camera per run: the test episodes share its detectors and mask resolution
        model = restore_model(open_run(path), tests[0])
        per_episode = []
        for data in tests:
            pred, _, _ = predict(model, data)
            post = postprocess(pred, data.label_specs, data.fps)
            per_episode.append(post[label].ravel())
        out.append(np.concatenate(per_episode))
    return np.stack(out)


def trivial(mean: float, tests: list[TrainingData], label: str) -> np.ndarray:
    """``[1, frame]``: the training mean, post-processed as a prediction."""
    out = []
    for data in tests:
        const = {label: np.full((len(data), 1), mean)}
        out.append(postprocess(const, data.label_specs, data.fps)[label].ravel())
    return np.concatenate(out)[None, :]


def shares(counts: np.ndarray) -> dict[int, float]:
    """``{count: fraction of frames}``."""
    values, n = np.unique(counts.astype(int), return_counts=True)
    return {int(v): float(k / counts.size) for v, k in zip(values, n, strict=True)}


def markdown(entry: dict[str, Any]) -> str:
    """The entry as a table: bias [95 % CI] / RMSE per true count, each design a row."""
    counts = sorted({b["count"] for bins in entry["designs"].values() for b in bins})
    train, test = entry["train_share"], entry["test_share"]
    head = "| design | RMSE (every seed's frames) | " + " | ".join(f"{c}" for c in counts) + " |"
    lines = [
        f"# Errors by true count: {entry['key']} ({entry['label']})",
        "",
        "Each cell: bias (mean prediction - truth) [95 % CI over seeds and test "
        "episodes] / RMSE, post-processed predictions of every seed.",
        "",
        head,
        "|" + "---|" * (len(counts) + 2),
        "| share of test frames | | "
        + " | ".join(f"{test.get(str(c), 0):.1%}" for c in counts)
        + " |",
        "| share of training frames | | "
        + " | ".join(f"{train.get(str(c), 0):.1%}" for c in counts)
        + " |",
    ]
    for design, bins in entry["designs"].items():
        by = {b["count"]: b for b in bins}
        cells = [
            f"{by[c]['bias']['mean']:+.2f} [{by[c]['bias']['ci95'][0]:+.2f}, "
            f"{by[c]['bias']['ci95'][1]:+.2f}] / {by[c]['rmse']:.2f}"
            if c in by
            else ""
            for c in counts
        ]
        lines.append(f"| {design} | {entry['rmse'][design]:.3f} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def plot(entry: dict[str, Any], path: Path) -> Path:
    """Bias against true count per design (95 % intervals), shares of frames below."""
    fig, (ax, bx) = plt.subplots(2, 1, figsize=(7, 6), sharex=True,
                                 gridspec_kw={"height_ratios": [3, 1]})  # fmt: skip
    for i, (design, bins) in enumerate(entry["designs"].items()):
        x = np.array([b["count"] for b in bins]) + (i - 2) * 0.06
        y = np.array([b["bias"]["mean"] for b in bins])
        lo = y - np.array([b["bias"]["ci95"][0] for b in bins])
        hi = np.array([b["bias"]["ci95"][1] for b in bins]) - y
        ax.errorbar(x, y, yerr=[lo, hi], marker="o", ms=3, capsize=2, label=design)
    ax.axhline(0, color="k", lw=0.5)
    ax.set_ylabel("bias: prediction - truth")
    ax.set_title(f"{entry['key']}: {entry['label']} errors by true count")
    ax.legend(fontsize=7)
    for name, share, off in (
        ("test", entry["test_share"], -0.2),
        ("train", entry["train_share"], 0.2),
    ):
        c = np.array([int(k) for k in share])
        bx.bar(c + off, [share[k] for k in share], width=0.4, label=f"{name} frames")
    bx.set_xlabel("true count")
    bx.set_ylabel("share")
    bx.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--key", required=True, help="the entry's name in the JSON")
    ap.add_argument("--runs", type=Path, required=True, help="RUNS/<design>-seed<i>")
    ap.add_argument("--episodes", type=Path, required=True, help="EPISODES/train-<i>, test-<i>")
    ap.add_argument("--train-episodes", type=int, required=True)
    ap.add_argument("--test-episodes", type=int, required=True)
    ap.add_argument("--label", required=True, help="a COUNT label, e.g. people_count")
    ap.add_argument("--out", type=Path, default=RESULTS / "errors_by_count.json")
    args = ap.parse_args()
    label = args.label
    tests = [
        TrainingData.from_dataset(open_dataset(args.episodes / f"test-{i}"), "test")
        .with_labels((label,))
        for i in range(args.test_episodes)
    ]  # fmt: skip
    true = np.concatenate([np.asarray(d.labels[label]).ravel() for d in tests])
    episode = np.concatenate([np.full(len(d), i) for i, d in enumerate(tests)])
    train = np.concatenate([
        open_dataset(args.episodes / f"train-{i}").labels("train")[label].ravel()
        for i in range(args.train_episodes)
    ])  # fmt: skip
    preds = {d: predictions(r, tests, label) for d, r in design_runs(args.runs).items()}
    preds["trivial"] = trivial(float(train.mean()), tests, label)
    bins: dict[str, tuple[CountBin, ...]] = {
        d: errors_by_count(p, true, episode) for d, p in preds.items()
    }
    entry = {
        "key": args.key,
        "label": label,
        "runs": str(args.runs),
        "episodes": str(args.episodes),
        "train_episodes": args.train_episodes,
        "test_episodes": args.test_episodes,
        "train_share": {str(k): v for k, v in shares(train).items()},
        "test_share": {str(k): v for k, v in shares(true).items()},
        "rmse": {d: float(np.sqrt(np.mean((p - true[None, :]) ** 2))) for d, p in preds.items()},
        "designs": {d: [b.as_json() for b in bs] for d, bs in bins.items()},
    }
    stem = f"{args.out.stem}_{args.key}"
    (args.out.parent / f"{stem}.md").write_text(markdown(entry))
    plot(entry, args.out.parent / f"{stem}.png")
    print(markdown(entry))
    merged = json.loads(args.out.read_text()) if args.out.is_file() else {}
    merged[args.key] = entry | {
        "machine": machine(),
        "command": " ".join(["python", *sys.argv]),
    }
    write_result(args.out, merged)


if __name__ == "__main__":
    main()
