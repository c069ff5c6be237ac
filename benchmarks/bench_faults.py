"""Reliability under faults: repeated trials per fault class, what survived, what was lost.

Classes (each trial runs the real command line in a subprocess):

- ``render_kill``: `render` killed (SIGKILL of its process group) at a random moment, then
  resumed; survived = the resumed dataset is byte-identical to an uninterrupted one and no
  finished shard was rewritten. Data lost = finished shards rewritten.
- ``train_kill``: `train` killed at a random moment after its first checkpoint, then resumed;
  survived = it finishes all steps, the checkpoint was never torn and history.jsonl has each
  evaluation step exactly once. Data lost = checkpointed steps repeated. Each trial records
  whether the kill landed mid-run (the checkpoint's step below the total).
- ``corruption``: each damage kind of a dataset (19: missing, truncated, empty, bit-flipped,
  grown shards, a bad .npy header, edited shard metadata, labels, scales and checksums,
  swapped shards, edited, stripped, truncated, foreign or missing manifests, an unfinished
  render) x each reader of datasets (train, sweep, prune, export-exr); survived = the reader
  refuses with exit 2 and one line naming the damaged file (or what is wrong), and writes
  no result (never trains, sweeps, prunes or exports from it).
- ``recording_corruption``: each damage kind of a sim2real recording x `report sim2real`;
  survived = the same one-line refusal and no report.
- ``concurrent_writers``: two `render` commands into one directory at once; survived = one
  fails at once with the writer-lock message and the other's dataset verifies.
- ``disk_full``: `render` and `train` writing into a real tmpfs too small for their output
  (root only: mounted here, skipped with a reason elsewhere); survived = `render` is first
  refused up front (exit 2, one line: more than the free disk, pass --yes) with nothing
  written; then with --yes (and `train`) exit 1 with one line saying no space is left,
  what was finished stays intact, and after the tmpfs is grown the same command finishes
  (render: byte-identical to an uninterrupted render, no finished shard rewritten; train:
  every evaluation step once).

- ``resume_other_path`` (issue 39): `train` started with relative paths from one folder and
  killed at a random moment, then resumed from another folder through another spelling of
  its paths (each of them, --trials times): absolute, via ``..``, its dataset moved, or
  run and dataset both moved; survived = the run resumes from its checkpoint (not from the
  start) and finishes every step. Also `pipeline` run again with --out spelled absolute from elsewhere: survived =
  every run is read back, not trained again, with the same figures.
- ``unfinished_run``: `train` killed mid-run, then each reader of a run (`export-masks`,
  `prune`, `report robustness`); survived = refused with exit 2 and one line saying the
  training did not finish, nothing written; with --allow-unfinished it proceeds and its
  output says "unfinished" (masks.json and the print sheet, prune.json, the robustness
  report).
- ``stale_export``: a smaller export into the folder of a larger one, an export into a
  folder holding a file of the user's, `export-masks` killed at random moments while it
  replaces an earlier export, `train --no-resume` over a finished run, and `pipeline`
  with other --pixels in the same --out; survived = the folder holds exactly the files its
  masks.json lists (the old export whole, or the new one whole), the user's folder is
  refused in one line and untouched, one TensorBoard event file and history of the new
  training only, and metrics.json names the earlier design's folders as not its own.
- ``huge_job``: `render patches` of 10^7 and 10^9 frames; survived = refused within a
  minute with exit 2 and one line giving the estimate and --yes, nothing written.
- ``sigterm``: `render` with 2 workers sent SIGTERM (its process) or SIGINT (its process
  group, as Ctrl-C) at a random moment, and `train` sent SIGTERM; survived = exit 128 +
  the signal with one line, no traceback or BrokenPipe, no process of its group left, and
  the same command resumes to a dataset byte-identical to an uninterrupted one (no
  finished shard rewritten) or to every training step once.

Every trial records ``survived``; ``silent_or_wrong_outcomes`` counts those that did not
(a silent success where a refusal was due, a wrong result, a traceback).

A trial whose check itself crashes (a file missing, a timeout) is recorded as not survived,
with the error; the benchmark goes on.

Usage:
    PYTHONPATH=. .venv/bin/python benchmarks/bench_faults.py [--trials 10]
        [--only sigterm,huge_job] [--out benchmarks/results/faults.json]
    (writes benchmarks/results/faults.json; --only runs the named classes alone)
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from functools import partial
from pathlib import Path

import numpy as np

from mincam_render.core import strict_json

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from provenance import machine  # noqa: E402

RENDER = ["render", "patches", "--frames", "40", "--shard-frames", "8", "--detectors", "2"]
RENDER += ["--mask-res", "8", "--spp", "2", "--seed", "5", "--no-progress", "--workers", "0"]
TRAIN_STEPS = 3000  # about 6 s here: the kill lands mid-run, after the first checkpoint
TRAIN = ["--steps", str(TRAIN_STEPS), "--eval-every", "20", "--batch-size", "8"]
TRAIN += ["--patience", "1000"]


def _cli(args, env=None, **kw) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "mincam_render.cli.main", *args],
        env=dict(os.environ, PYTHONPATH=str(REPO), **(env or {})),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        **kw,
    )


def _run(args, **kw) -> subprocess.CompletedProcess:
    p = _cli(args, **kw)
    out, err = p.communicate(timeout=600)
    return subprocess.CompletedProcess(args, p.returncode, out, err)


def _files(root: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(root)): p.read_bytes()
        for p in sorted(root.rglob("*"))
        if p.is_file() and p.name not in ("render_log.jsonl", ".writer.lock")
    }


def _wait_for(predicate, p: subprocess.Popen, timeout_s: float = 240) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if p.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f"no progress before the kill: {p.communicate()[1][-500:]}")
        time.sleep(0.01)


def render_kill(tmp: Path, reference: Path, rng) -> dict:
    from mincam_render.data.render_job import FRAME_DELAY_ENV

    out = tmp / "killed"
    p = _cli([*RENDER, "--out", str(out)], env={FRAME_DELAY_ENV: "0.05"})
    _wait_for(lambda: (out / "manifest.json").exists(), p)
    time.sleep(float(rng.uniform(0.0, 2.0)))
    os.killpg(p.pid, signal.SIGKILL)
    p.wait(timeout=30)
    # finished = its .json written (after its .npy); an .npy alone is unfinished work
    shards = sorted((out / "shards").glob("shard-*.json")) if (out / "shards").exists() else []
    npys = [s.with_suffix(".npy") for s in shards]
    before = {s.name: s.stat().st_mtime_ns for s in npys}
    done = _run([*RENDER, "--out", str(out)])
    rewritten = [n for n, t in before.items() if (out / "shards" / n).stat().st_mtime_ns != t]
    ok = done.returncode == 0 and _files(out) == _files(reference) and not rewritten
    return {
        "survived": ok,
        "lost": len(rewritten),
        "finished_before_kill": len(before),
        "killed_mid_run": len(before) < 5,  # 40 frames in 5 shards
    }


def train_kill(tmp: Path, dataset: Path, rng) -> dict:
    out = tmp / "run"
    p = _cli(["train", str(dataset), "--out", str(out), *TRAIN])
    _wait_for(lambda: (out / "checkpoint.pt").exists(), p)
    time.sleep(float(rng.uniform(0.0, 3.0)))
    os.killpg(p.pid, signal.SIGKILL)
    p.wait(timeout=30)
    import torch

    checkpointed = torch.load(out / "checkpoint.pt", weights_only=False)["step"]
    done = _run(["train", str(dataset), "--out", str(out), *TRAIN])
    steps = [json.loads(line)["step"] for line in (out / "history.jsonl").read_text().splitlines()]
    unique = len(steps) == len(set(steps)) and steps == sorted(steps)
    metrics = json.loads((out / "metrics.json").read_text()) if done.returncode == 0 else {}
    ok = done.returncode == 0 and unique and metrics.get("steps") == TRAIN_STEPS
    return {
        "survived": ok,
        "lost": 0 if unique else len(steps) - len(set(steps)),
        "checkpoint_step_at_kill": int(checkpointed),
        "killed_mid_run": int(checkpointed) < TRAIN_STEPS,
    }


def _edit_json(path: Path, change) -> None:
    data = json.loads(path.read_text())
    change(data)
    path.write_text(strict_json.dumps(data, indent=None))


def _rewrite(path: Path, change) -> None:
    path.write_bytes(change(bytearray(path.read_bytes())))


def _flip(data: bytearray, at: int, bits: int) -> bytearray:
    data[at] ^= bits
    return data


def _swap_shards(root: Path) -> None:
    from mincam_render.data import dataset as ds

    for a, b in zip(ds.shard_paths(root, 1), ds.shard_paths(root, 2), strict=True):
        tmp = a.with_suffix(".swap")
        a.rename(tmp)
        b.rename(a)
        tmp.rename(b)


def _mark_incomplete(root: Path) -> None:
    """As a killed render leaves it, written by the writer (its checksum is right)."""
    from mincam_render.data import dataset as ds

    m = ds.read_manifest(root)
    m["shards"][2], m["complete"] = None, False
    ds.write_manifest(root, m)


def _strip_checksum_and_edit(m: dict) -> None:
    del m["manifest_sha256"]
    _move_mask_away(m)


def _on(path_of, change, names: str | None = None):
    """A damage: ``change`` the file ``path_of(root)``; the error must name it (or ``names``)."""

    def damage(root: Path) -> str:
        path = path_of(root)
        change(path)
        return names or path.name

    return damage


def _json(change):
    """A change of a file: edit its parsed JSON in place with ``change(data)``."""
    return lambda path: _edit_json(path, change)


def dataset_damage() -> dict:
    """``{kind: damage(root) -> what the error must name}`` for a copy of a dataset."""
    from mincam_render.data import dataset as ds

    def npy(root):
        return ds.shard_paths(root, 1)[0]

    def meta(root):
        return ds.shard_paths(root, 1)[1]

    def manifest(root):
        return root / ds.MANIFEST_NAME

    splits = {"train": [0, 40], "val": [0, 40], "test": [0, 40]}
    return {
        "missing-shard": _on(npy, Path.unlink),
        "truncated-shard": _on(npy, lambda p: _rewrite(p, lambda d: d[:300])),
        "empty-shard": _on(npy, lambda p: p.write_bytes(b"")),
        "flipped-byte": _on(npy, lambda p: _rewrite(p, lambda d: _flip(d, len(d) // 2, 0x40))),
        "appended-bytes": _on(npy, lambda p: _rewrite(p, lambda d: d + b"\0" * 64)),
        "corrupt-npy-header": _on(npy, lambda p: _rewrite(p, lambda d: _flip(d, 20, 0x20))),
        "truncated-shard-metadata": _on(meta, lambda p: _rewrite(p, lambda d: d[:40])),
        "edited-label": _on(meta, _json(_edit_first_label)),
        "edited-frame-scale": _on(meta, _json(_scale_first_frame)),
        "zeroed-shard-checksum": _on(meta, _json(lambda m: m.update(transport_sha256="0" * 64))),
        "swapped-shards": _on(meta, lambda p: _swap_shards(p.parents[1])),
        "edited-manifest-spp": _on(manifest, _json(lambda m: m["job"]["render"].update(spp=99))),
        "edited-manifest-camera": _on(manifest, _json(_move_mask_away)),
        "edited-manifest-splits": _on(manifest, _json(lambda m: m.update(splits=splits))),
        "stripped-checksum-edited-camera": _on(manifest, _json(_strip_checksum_and_edit)),
        "truncated-manifest": _on(manifest, lambda p: _rewrite(p, lambda d: d[:100])),
        "manifest-not-ours": _on(manifest, lambda p: p.write_text('{"format": "other"}')),
        "no-manifest": _on(manifest, Path.unlink),
        "unfinished-render": _on(manifest, lambda p: _mark_incomplete(p.parent), "incomplete"),
    }


def _move_mask_away(m: dict) -> None:
    m["camera"]["mask_distance_m"] *= 10


def _scale_first_frame(meta: dict) -> None:
    """A frame's power-of-two storage scale times 2**30: |T| of that frame x 1e9."""
    meta["frames"][0]["scale"] *= 2.0**30


def _edit_first_label(meta: dict) -> None:
    name = next(iter(meta["labels"]))
    meta["labels"][name][0] = [v + 1.0 for v in meta["labels"][name][0]]


def dataset_readers(root: Path, run: Path, out: Path) -> dict[str, list[str]]:
    """The commands that read a dataset, each writing its result into ``out``."""
    quick = ["--steps", "4", "--eval-every", "2", "--batch-size", "4", "--out", str(out)]
    return {
        "train": ["train", str(root), *quick],
        "sweep": ["sweep", str(root), *quick, "--pixels", "1", "--baselines", "1x1"],
        "prune": ["prune", str(root), *quick, "--run", str(run)],
        "export-exr": ["export-exr", str(root), "--frames", "0-39", "--out", str(out)],
    }


def _refused(done: subprocess.CompletedProcess, name: str, out: Path) -> dict:
    lines = [ln for ln in done.stderr.splitlines() if ln.startswith("Error:")]
    refused = done.returncode == 2 and len(lines) == 1 and name in lines[0]
    used = out.exists() and any(p.name != ".writer.lock" for p in out.iterdir())
    return {
        "survived": refused and not used,
        "used_corrupt_data": done.returncode == 0 or used,
        "lost": 0,
        "exit_code": done.returncode,
        "error": lines[0][:300] if lines else done.stderr[-300:],
    }


def corruption(tmp: Path, dataset: Path, run: Path, how: str, reader: str) -> dict:
    root = tmp / "damaged"
    shutil.copytree(dataset, root)
    name = dataset_damage()[how](root)
    out = tmp / "out"
    done = _run(dataset_readers(root, run, out)[reader])
    return {**_refused(done, name, out), "damage": how, "reader": reader}


def recording_damage() -> dict:
    """``{kind: damage(root) -> what the error must name}`` for a copy of a recording."""

    def edit_csv(path: Path) -> None:
        lines = path.read_text().splitlines()
        cells = lines[3].split(",")
        cells[-1] = repr(float(cells[-1]) + 0.5)
        lines[3] = ",".join(cells)
        path.write_text("\n".join(lines) + "\n")

    def file(name):
        return lambda root: root / name

    return {
        "edited-measurement": _on(file("measurements.csv"), edit_csv),
        "edited-label": _on(file("labels.csv"), edit_csv),
        "truncated-masks": _on(file("masks.npy"), lambda p: _rewrite(p, lambda d: d[:-7])),
        "edited-injected": _on(file("injected.json"), lambda p: _rewrite(p, lambda d: d + b" ")),
        "missing-measurements": _on(file("measurements.csv"), Path.unlink),
        "missing-recording-json": _on(file("recording.json"), Path.unlink),
        "truncated-recording-json": _on(
            file("recording.json"), lambda p: _rewrite(p, lambda d: d[:50])
        ),
    }


def recording_corruption(tmp: Path, recording: Path, how: str) -> dict:
    root = tmp / "damaged"
    shutil.copytree(recording, root)
    name = recording_damage()[how](root)
    out = tmp / "out"
    done = _run(["report", "sim2real", str(root), "--out", str(out), "--spp", "1", "--steps", "10"])
    return {**_refused(done, name, out), "damage": how, "reader": "report sim2real"}


def concurrent_writers(tmp: Path) -> dict:
    from mincam_render.data import dataset as ds

    out = tmp / "shared"
    a, b = _cli([*RENDER, "--out", str(out)]), _cli([*RENDER, "--out", str(out)])
    results = [(p.wait(timeout=600), p.communicate()[1]) for p in (a, b)]
    codes = sorted(code for code, _ in results)
    busy = any("another" in err and code != 0 for code, err in results)
    intact = (out / "manifest.json").exists() and ds.open_dataset(out).verify() == []
    return {
        "survived": codes[0] == 0 and (codes[1] == 0 or busy) and intact,
        "lost": 0,
        "exit_codes": codes,
    }


class NoTmpfs(RuntimeError):
    """No tmpfs can be mounted here (not root): the full-disk class is skipped."""


class _TinyDisk:
    """A real tmpfs of ``size_bytes`` at ``mnt`` (root only), grown by :meth:`grow`."""

    def __init__(self, mnt: Path, size_bytes: int) -> None:
        self.mnt = mnt
        mnt.mkdir()
        size = f"size={max(4096, size_bytes // 4096 * 4096)}"
        r = subprocess.run(
            ["mount", "-t", "tmpfs", "-o", size, "tmpfs", str(mnt)],
            capture_output=True,
            text=True,
            timeout=20,
        )
        if r.returncode != 0:
            raise NoTmpfs(r.stderr.strip() or "mount failed")

    def grow(self) -> None:
        subprocess.run(["mount", "-o", "remount,size=256m", str(self.mnt)], check=True, timeout=20)

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        subprocess.run(["umount", str(self.mnt)], capture_output=True, timeout=20)


def _size(root: Path) -> int:
    return sum(p.stat().st_size for p in root.rglob("*") if p.is_file())


def _no_space(done: subprocess.CompletedProcess) -> bool:
    lines = [ln for ln in done.stderr.splitlines() if ln.startswith("Error:")]
    return done.returncode == 1 and len(lines) == 1 and "No space left" in lines[0]


def disk_full_render(tmp: Path, reference: Path) -> dict:
    from mincam_render.data import dataset as ds

    with _TinyDisk(tmp / "mnt", _size(reference) // 2) as disk:
        out = disk.mnt / "ds"
        # the up-front estimate sees the small disk: refused, nothing written
        refused = _run([*RENDER, "--out", str(out)])
        foreseen = _one_line(refused, "more than the free disk", "--yes") and not out.exists()
        # --yes: rendered anyway, so the disk fills while shards are written
        first = _run([*RENDER, "--yes", "--out", str(out)])
        manifest = (
            json.loads((out / ds.MANIFEST_NAME).read_text())
            if (out / ds.MANIFEST_NAME).exists()
            else None
        )
        finished = [i for i, r in enumerate((manifest or {}).get("shards", [])) if r]
        intact = all(ds.verify_shard(out, i, manifest["shards"][i])[0] for i in finished)
        before = {i: ds.shard_paths(out, i)[0].stat().st_mtime_ns for i in finished}
        disk.grow()
        done = _run([*RENDER, "--yes", "--out", str(out)])
        rewritten = [
            i for i, t in before.items() if ds.shard_paths(out, i)[0].stat().st_mtime_ns != t
        ]
        ok = (
            foreseen
            and refused.returncode == 2
            and _no_space(first)
            and intact
            and done.returncode == 0
            and _files(out) == _files(reference)
        )
        return {
            "survived": ok and not rewritten,
            "lost": len(rewritten),
            "what": "render",
            "finished_before_full": len(finished),
            "refused_up_front": foreseen and refused.returncode == 2,
            "first_exit_code": first.returncode,
        }


def disk_full_train(tmp: Path, dataset: Path, finished_run: Path) -> dict:
    with _TinyDisk(tmp / "mnt", _size(finished_run) // 2) as disk:
        out = disk.mnt / "run"
        first = _run(["train", str(dataset), "--out", str(out), *TRAIN])
        disk.grow()
        done = _run(["train", str(dataset), "--out", str(out), *TRAIN])
        steps = [json.loads(ln)["step"] for ln in (out / "history.jsonl").read_text().splitlines()]
        unique = len(steps) == len(set(steps)) and steps == sorted(steps)
        ok = _no_space(first) and done.returncode == 0 and unique
        return {
            "survived": ok,
            "lost": len(steps) - len(set(steps)),
            "what": "train",
            "first_exit_code": first.returncode,
        }


# ---- issue 39: paths, unfinished runs, stale exports, huge jobs, stop signals ------------


def _one_line(done: subprocess.CompletedProcess, *needles: str) -> bool:
    """Exactly one ``Error:`` line naming every needle, and no traceback."""
    lines = [ln for ln in done.stderr.splitlines() if ln.startswith("Error:")]
    clean = "Traceback" not in done.stderr and "BrokenPipe" not in done.stderr
    return clean and len(lines) == 1 and all(n in lines[0] for n in needles)


def _history_steps(run: Path) -> list[int]:
    return [json.loads(ln)["step"] for ln in (run / "history.jsonl").read_text().splitlines()]


def _kill_after_checkpoint(args: list[str], run: Path, rng, **kw) -> int:
    """Start `train` ARGS, SIGKILL it at a random moment after its first checkpoint."""
    p = _cli(args, **kw)
    _wait_for(lambda: (run / "checkpoint.pt").exists(), p)
    time.sleep(float(rng.uniform(0.0, 2.0)))
    os.killpg(p.pid, signal.SIGKILL)
    p.wait(timeout=30)
    import torch

    return int(torch.load(run / "checkpoint.pt", weights_only=False)["step"])


#: How a resumed run names its paths: (dataset, run) from the second folder ``b``.
RESPELLINGS = {
    "absolute": lambda a, b: (a / "ds", a / "run"),
    "dot-dot": lambda a, b: (Path("..") / "a" / "ds", Path("..") / "a" / "run"),
    "dataset-moved": lambda a, b: (a / "moved", a / "run"),
    "both-moved": lambda a, b: (b / "moved", b / "run"),
}


def resume_other_path(tmp: Path, reference: Path, how: str, rng) -> dict:
    a, b = tmp / "a", tmp / "b"
    a.mkdir()
    b.mkdir()
    shutil.copytree(reference, a / "ds")
    step = _kill_after_checkpoint(["train", "ds", "--out", "run", *TRAIN], a / "run", rng, cwd=a)
    if how == "dataset-moved":
        (a / "ds").rename(a / "moved")
    if how == "both-moved":
        (a / "ds").rename(b / "moved")
        (a / "run").rename(b / "run")
    ds, run = RESPELLINGS[how](a, b)
    done = _run(["train", str(ds), "--out", str(run), *TRAIN], cwd=b)
    resumed = f"at step {step}" in done.stderr and "resumed" in done.stderr
    steps = _history_steps(b / run) if done.returncode == 0 else []
    ok = done.returncode == 0 and resumed and steps == sorted(set(steps))
    metrics = json.loads((b / run / "metrics.json").read_text()) if ok else {}
    return {
        "survived": ok and metrics.get("steps") == TRAIN_STEPS,
        "lost": 0 if resumed else step,
        "respelling": how,
        "checkpoint_step_at_kill": step,
        "killed_mid_run": step < TRAIN_STEPS,
        "error": "" if ok else done.stderr[-300:],
    }


PIPELINE = ["pipeline", "--family", "patches", "--train-frames", "60", "--val-frames", "30",
            "--test-frames", "30", "--test-episodes", "2", "--seeds", "2", "--steps", "30",
            "--workers", "0", "--spp", "2", "--detectors", "2", "--mask-res", "8",
            "--baseline-grid", "2x2"]  # fmt: skip


def pipeline_other_path(tmp: Path) -> dict:
    """`pipeline` into ``main`` from ``tmp``, then into its absolute path from elsewhere."""
    (tmp / "elsewhere").mkdir()
    metrics = tmp / "main" / "metrics.json"
    first = _run([*PIPELINE, "--pixels", "2", "--out", "main"], cwd=tmp)
    before = json.loads(metrics.read_text()) if first.returncode == 0 else {"designs": {}}
    again = _run([*PIPELINE, "--pixels", "2", "--out", str(tmp / "main")], cwd=tmp / "elsewhere")
    after = json.loads(metrics.read_text()) if again.returncode == 0 else {"designs": {}}
    same = all(
        after["designs"].get(n, {}).get(k) == d[k]
        for n, d in before["designs"].items()
        for k in ("error", "steps", "train_wall_time_s")  # read back, not trained again
    )
    ok = first.returncode == again.returncode == 0 and bool(before["designs"]) and same
    return {
        "survived": ok,
        "lost": 0,
        "respelling": "pipeline --out absolute from elsewhere",
        "error": "" if ok else (first.stderr + again.stderr)[-400:],
    }


def _reader(command: str, run: Path, ds: Path, out: Path) -> list[str]:
    return {
        "export-masks": ["export-masks", str(run), "--task", "t", "--out", str(out)],
        "prune": ["prune", str(ds), "--steps", "4", "--eval-every", "2", "--batch-size", "4",
                  "--run", str(run), "--out", str(out)],
        "report robustness": ["report", "robustness", str(run), "--data", str(ds), "--draws",
                              "2", "--levels", "0,1", "--out", str(out)],
    }[command]  # fmt: skip


def _marked_unfinished(command: str, out: Path) -> bool:
    """Whether a reader's output says it came from an unfinished run."""
    if command == "export-masks":
        sidecar = json.loads((out / "t" / "masks.json").read_text())
        sheet = (out / "t" / "print_sheet.svg").read_text()
        return sidecar["provenance"]["training"].startswith("unfinished") and "UNFINISHED" in sheet
    if command == "prune":
        records = json.loads((out / "prune.json").read_text())
        return all(r["run_training"].startswith("unfinished") for r in records)
    designs = json.loads((out / "robustness.json").read_text())
    return all(d["name"].endswith("(unfinished)") for d in designs)


def unfinished_run(tmp: Path, reference: Path, rng) -> list[dict]:
    """One killed run, then every reader without and with --allow-unfinished."""
    run = tmp / "run"
    step = _kill_after_checkpoint(["train", str(reference), "--out", str(run), *TRAIN], run, rng)
    trials = []
    for command in ("export-masks", "prune", "report robustness"):
        out = tmp / command.replace(" ", "-")
        refused = _run(_reader(command, run, reference, out))
        wrote = out.exists() and any(out.iterdir())
        ok = refused.returncode == 2 and _one_line(refused, "did not finish") and not wrote
        allowed = _run([*_reader(command, run, reference, out), "--allow-unfinished"])
        marked = allowed.returncode == 0 and _marked_unfinished(command, out)
        trials.append({
            "survived": ok and marked,
            "lost": 0,
            "reader": command,
            "checkpoint_step_at_kill": step,
            "killed_mid_run": step < TRAIN_STEPS,
            "refused": ok,
            "marked_when_allowed": marked,
            "error": refused.stderr[-300:] if not ok else allowed.stderr[-300:] if not marked else "",
        })  # fmt: skip
    return trials


def _export_whole(folder: Path) -> bool:
    """The folder holds exactly the files its masks.json lists (or nothing at all)."""
    if not folder.exists():
        return True
    sidecar = json.loads((folder / "masks.json").read_text())
    files = sidecar["files"]
    listed = {*files["png"], files["exr"], files["svg"], "masks.json"} | (
        {files["pdf"]} if files["pdf"] else set()
    )
    return {p.name for p in folder.iterdir()} == listed


def stale_export(tmp: Path, reference: Path, run: Path, small_run: Path) -> list[dict]:
    """A smaller export over a larger, a folder of the user's, train --no-resume."""
    out = tmp / "masks"
    big = _run(["export-masks", str(run), "--task", "t", "--out", str(out)])
    small = _run(["export-masks", str(small_run), "--task", "t", "--out", str(out)])
    smaller = big.returncode == small.returncode == 0 and _export_whole(out / "t")
    smaller = smaller and json.loads((out / "t" / "masks.json").read_text())["masks"] == 1
    (out / "t" / "notes.txt").write_text("the user's")
    before = _files(out)
    refused = _run(["export-masks", str(run), "--task", "t", "--out", str(out)])
    mine = refused.returncode == 2 and _one_line(refused, "notes.txt") and _files(out) == before
    again = tmp / "run"
    shutil.copytree(run, again)
    fresh = _run(["train", str(reference), "--out", str(again), "--no-resume",
                  "--steps", "40", "--eval-every", "20", "--batch-size", "8"])  # fmt: skip
    events = list(again.glob("events.out.tfevents.*"))
    clean = fresh.returncode == 0 and len(events) == 1 and _history_steps(again) == [20, 40]
    return [
        {"survived": smaller, "lost": 0, "what": "smaller export over a larger one"},
        {"survived": mine, "lost": 0, "what": "export into a folder of the user's"},
        {"survived": clean, "lost": 0, "what": "train --no-resume over a finished run"},
    ]


def export_kill(tmp: Path, run: Path, small_run: Path, rng) -> dict:
    """`export-masks` SIGKILLed while it replaces an earlier export: old or new, whole."""
    out = tmp / "masks"
    assert _run(["export-masks", str(small_run), "--task", "t", "--out", str(out)]).returncode == 0
    p = _cli(["export-masks", str(run), "--task", "t", "--out", str(out)])
    time.sleep(float(rng.uniform(0.5, 4.0)))
    os.killpg(p.pid, signal.SIGKILL)
    p.wait(timeout=30)
    whole = _export_whole(out / "t")
    done = _run(["export-masks", str(run), "--task", "t", "--out", str(out)])
    final = done.returncode == 0 and _export_whole(out / "t")
    hidden = [q.name for q in out.iterdir() if q.name.startswith(".")]
    return {
        "survived": whole and final and not hidden,
        "lost": 0,
        "what": "export-masks killed while replacing an export",
        "killed_mid_run": p.returncode != 0,
    }


def pipeline_other_pixels(tmp: Path) -> dict:
    """`pipeline` with other --pixels in the same --out: its metrics.json names the old design."""
    first = _run([*PIPELINE, "--pixels", "2", "--out", str(tmp / "main")])
    other = _run([*PIPELINE, "--pixels", "1", "--out", str(tmp / "main")])
    ok = first.returncode == other.returncode == 0
    left = json.loads((tmp / "main" / "metrics.json").read_text()).get(
        "not_of_this_comparison", {}
    ) if ok else {}  # fmt: skip
    ok = ok and left.get("masks") == ["mincam-2px"] and "mincam-2px-seed0" in left.get("runs", [])
    return {"survived": ok, "lost": 0, "what": "pipeline with other --pixels in one --out"}


def huge_job(tmp: Path, frames: int) -> dict:
    out = tmp / "huge"
    t0 = time.monotonic()
    done = _run(["render", "patches", "--frames", str(frames), "--out", str(out)])
    seconds = time.monotonic() - t0
    ok = done.returncode == 2 and _one_line(done, "pass --yes", "frames x") and not out.exists()
    return {
        "survived": ok and seconds < 60,
        "lost": 0,
        "frames": frames,
        "seconds_to_refuse": seconds,
        "error": [ln for ln in done.stderr.splitlines() if ln.startswith("Error:")][:1],
    }


def _group_gone(pgid: int, timeout_s: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.05)
    return False


def sigterm_render(tmp: Path, reference: Path, rng, sig: signal.Signals) -> dict:
    from mincam_render.data.render_job import FRAME_DELAY_ENV

    out = tmp / "stopped"
    pool = [*RENDER[:-1], "2"]  # --workers 2
    p = _cli([*pool, "--out", str(out)], env={FRAME_DELAY_ENV: "0.05"})
    _wait_for(lambda: (out / "manifest.json").exists(), p)
    time.sleep(float(rng.uniform(0.0, 2.0)))
    (os.kill if sig == signal.SIGTERM else os.killpg)(p.pid, sig)  # Ctrl-C: the whole group
    _, err = p.communicate(timeout=60)
    stopped = subprocess.CompletedProcess([], p.returncode, "", err)
    finished = p.returncode == 0  # it ended before the signal
    clean = finished or (p.returncode == 128 + sig and _one_line(stopped, f"stopped by {sig.name}"))
    gone = _group_gone(p.pid)
    npys = sorted((out / "shards").glob("shard-*.json")) if (out / "shards").exists() else []
    before = {s.with_suffix(".npy").name: s.with_suffix(".npy").stat().st_mtime_ns for s in npys}
    done = _run([*pool, "--out", str(out)])
    rewritten = [n for n, t in before.items() if (out / "shards" / n).stat().st_mtime_ns != t]
    same = done.returncode == 0 and _files(out) == _files(reference)
    return {
        "survived": clean and gone and same and not rewritten,
        "lost": len(rewritten),
        "what": f"render, {sig.name}",
        "exit_code": p.returncode,
        "killed_mid_run": not finished,
        "finished_before_signal": len(before),
        "error": "" if clean else err[-400:],
    }


def sigterm_train(tmp: Path, reference: Path, rng) -> dict:
    run = tmp / "run"
    p = _cli(["train", str(reference), "--out", str(run), *TRAIN])
    _wait_for(lambda: (run / "checkpoint.pt").exists(), p)
    time.sleep(float(rng.uniform(0.0, 2.0)))
    os.kill(p.pid, signal.SIGTERM)
    _, err = p.communicate(timeout=60)
    stopped = subprocess.CompletedProcess([], p.returncode, "", err)
    finished = p.returncode == 0  # it ended before the signal
    clean = finished or (p.returncode == 143 and _one_line(stopped, "stopped by SIGTERM"))
    gone = _group_gone(p.pid)
    done = _run(["train", str(reference), "--out", str(run), *TRAIN])
    steps = _history_steps(run) if done.returncode == 0 else []
    ok = done.returncode == 0 and steps == sorted(set(steps)) and steps[-1:] == [TRAIN_STEPS]
    return {
        "survived": clean and ok and gone,
        "lost": len(steps) - len(set(steps)),
        "what": "train, SIGTERM",
        "exit_code": p.returncode,
        "killed_mid_run": not finished,
        "error": "" if clean else err[-400:],
    }


def _summary(trials: list[dict]) -> dict:
    return {
        "trials": len(trials),
        "killed_mid_run": sum(t.get("killed_mid_run", True) for t in trials),
        "survived": sum(t["survived"] for t in trials),
        "data_lost": sum(t["lost"] for t in trials),
        "details": trials,
    }


#: Classes to run (all when empty); set from --only.
ONLY: set[str] = set()


def _crashed(err: Exception) -> dict:
    """A trial whose check itself failed (a file missing, a timeout): not survived."""
    return {"survived": False, "lost": 0, "error": f"{type(err).__name__}: {err}"[-400:]}


def _trial(classes: dict, name: str, base: Path, trial) -> None:
    """Run ``trial(tmp)`` once; its record (or its crash, not survived) joins class ``name``."""
    _trials(classes, name, base, lambda tmp: [trial(tmp)])


def _trials(classes: dict, name: str, base: Path, trials) -> None:
    """Like :func:`_trial` for a function that returns several trials' records."""
    if ONLY and name not in ONLY:
        return
    tmp = Path(tempfile.mkdtemp(dir=base))
    try:
        records = trials(tmp)
    except NoTmpfs:
        raise
    except Exception as err:  # a crash of the check counts, it does not end the benchmark
        records = [_crashed(err)]
    for record in records:
        classes.setdefault(name, []).append(record)
        print(name, record, flush=True)


def _fixtures(base: Path) -> tuple[Path, Path, Path, Path]:
    """The intact dataset, finished runs of 2 and 1 pixels on it, a SURROGATE recording."""
    reference, run, s2r = base / "reference", base / "run", base / "s2r"
    small = base / "run-1px"
    assert _run([*RENDER, "--out", str(reference)]).returncode == 0
    assert _run(["train", str(reference), "--out", str(run), *TRAIN]).returncode == 0
    quick = ["--steps", "40", "--eval-every", "20", "--pixels", "1"]
    assert _run(["train", str(reference), "--out", str(small), *quick]).returncode == 0
    surrogate = ["report", "sim2real", "--surrogate", "patches", "--frames", "20"]
    assert _run([*surrogate, "--spp", "1", "--steps", "10", "--out", str(s2r)]).returncode == 0
    return reference, run, small, s2r / "surrogate_input"


def _issue39_trials(
    classes: dict, base: Path, runs: tuple[Path, Path, Path], trials: int, rng
) -> None:
    """Issue 39's classes: resume by other path, unfinished run, stale export, huge job, SIGTERM."""
    reference, run, small = runs
    for i in range(trials):
        for how in RESPELLINGS:
            _trial(
                classes,
                "resume_other_path",
                base,
                partial(resume_other_path, reference=reference, how=how, rng=rng),
            )
        _trial(
            classes, "stale_export", base, partial(export_kill, run=run, small_run=small, rng=rng)
        )
        sig = (signal.SIGTERM, signal.SIGINT)[i % 2]
        _trial(
            classes, "sigterm", base, partial(sigterm_render, reference=reference, rng=rng, sig=sig)
        )
    _trial(classes, "resume_other_path", base, pipeline_other_path)
    for _ in range(3):
        _trials(
            classes, "unfinished_run", base, partial(unfinished_run, reference=reference, rng=rng)
        )
    _trials(
        classes,
        "stale_export",
        base,
        partial(stale_export, reference=reference, run=run, small_run=small),
    )
    _trial(classes, "stale_export", base, pipeline_other_pixels)
    for _ in range(3):
        _trial(classes, "sigterm", base, partial(sigterm_train, reference=reference, rng=rng))
    for frames in (10**7, 10**9):
        _trial(classes, "huge_job", base, partial(huge_job, frames=frames))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=10, help="trials per kill/writer class")
    parser.add_argument(
        "--only", default="", help="comma-separated classes to run (default: all of them)"
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=REPO / "benchmarks" / "results" / "faults.json",
        help="result file (default: benchmarks/results/faults.json)",
    )
    args = parser.parse_args()
    ONLY.update(filter(None, args.only.split(",")))
    rng = np.random.default_rng(0)
    classes: dict[str, list[dict]] = {}
    started, host = time.monotonic(), machine()  # the tree as it was when the run began
    with tempfile.TemporaryDirectory() as base:
        base = Path(base)
        os.environ["MINCAM_RENDER_PLAN_CACHE"] = str(base / "plans")
        reference, run, small, recording = _fixtures(base)
        _issue39_trials(classes, base, (reference, run, small), args.trials, rng)
        for _ in range(args.trials):
            _trial(classes, "render_kill", base, lambda t: render_kill(t, reference, rng))
            _trial(classes, "train_kill", base, lambda t: train_kill(t, reference, rng))
            _trial(classes, "concurrent_writers", base, concurrent_writers)
        for how in dataset_damage():
            for reader in ("train", "sweep", "prune", "export-exr"):
                _trial(
                    classes,
                    "corruption",
                    base,
                    partial(corruption, dataset=reference, run=run, how=how, reader=reader),
                )
        for how in recording_damage():
            _trial(
                classes,
                "recording_corruption",
                base,
                partial(recording_corruption, recording=recording, how=how),
            )
        try:
            _trial(classes, "disk_full", base, lambda t: disk_full_render(t, reference))
            _trial(classes, "disk_full", base, lambda t: disk_full_train(t, reference, run))
        except NoTmpfs as err:  # not root: no tmpfs
            classes["disk_full"] = []
            print(f"disk_full skipped: {err}")
    result = {name: _summary(trials) for name, trials in classes.items()}
    result["corruption_kinds"] = {
        "dataset": list(dataset_damage()),
        "dataset_readers": ["train", "sweep", "prune", "export-exr"],
        "recording": list(recording_damage()),
        "recording_readers": ["report sim2real"],
    }
    result["silent_uses_of_corrupt_data"] = sum(
        t.get("used_corrupt_data", False)
        for k in ("corruption", "recording_corruption")
        for t in classes.get(k, [])
    )
    result["silent_or_wrong_outcomes"] = sum(
        not t["survived"] for trials in classes.values() for t in trials
    )
    result["machine"] = host
    result["wall_time_s"] = time.monotonic() - started
    path = args.out
    path.write_text(strict_json.dumps(result, indent=2) + "\n")
    for name, s in result.items():
        if isinstance(s, dict) and "trials" in s:
            print(f"{name}: {s['survived']}/{s['trials']} survived, data lost {s['data_lost']}")
    print(f"silent uses of corrupt data: {result['silent_uses_of_corrupt_data']}")
    print(f"silent or wrong outcomes: {result['silent_or_wrong_outcomes']}")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
