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
  (root only: mounted here, skipped with a reason elsewhere); survived = exit 1 with one
  line saying no space is left, what was finished stays intact, and after the tmpfs is
  grown the same command finishes (render: byte-identical to an uninterrupted render, no
  finished shard rewritten; train: every evaluation step once).

Usage:
    PYTHONPATH=. .venv/bin/python benchmarks/bench_faults.py [--trials 10]
    (writes benchmarks/results/faults.json)
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
            raise PermissionError(r.stderr.strip() or "mount failed")

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
        first = _run([*RENDER, "--out", str(out)])
        manifest = (
            json.loads((out / ds.MANIFEST_NAME).read_text())
            if (out / ds.MANIFEST_NAME).exists()
            else None
        )
        finished = [i for i, r in enumerate((manifest or {}).get("shards", [])) if r]
        intact = all(ds.verify_shard(out, i, manifest["shards"][i])[0] for i in finished)
        before = {i: ds.shard_paths(out, i)[0].stat().st_mtime_ns for i in finished}
        disk.grow()
        done = _run([*RENDER, "--out", str(out)])
        rewritten = [
            i for i, t in before.items() if ds.shard_paths(out, i)[0].stat().st_mtime_ns != t
        ]
        ok = (
            _no_space(first)
            and intact
            and done.returncode == 0
            and _files(out) == _files(reference)
        )
        return {
            "survived": ok and not rewritten,
            "lost": len(rewritten),
            "what": "render",
            "finished_before_full": len(finished),
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


def _summary(trials: list[dict]) -> dict:
    return {
        "trials": len(trials),
        "killed_mid_run": sum(t.get("killed_mid_run", True) for t in trials),
        "survived": sum(t["survived"] for t in trials),
        "data_lost": sum(t["lost"] for t in trials),
        "details": trials,
    }


def _trial(classes: dict, name: str, base: Path, trial) -> None:
    tmp = Path(tempfile.mkdtemp(dir=base))
    classes.setdefault(name, []).append(trial(tmp))
    print(name, classes[name][-1], flush=True)


def _fixtures(base: Path) -> tuple[Path, Path, Path]:
    """The intact dataset, a finished training run on it, and a SURROGATE recording."""
    reference, run, s2r = base / "reference", base / "run", base / "s2r"
    assert _run([*RENDER, "--out", str(reference)]).returncode == 0
    assert _run(["train", str(reference), "--out", str(run), *TRAIN]).returncode == 0
    surrogate = ["report", "sim2real", "--surrogate", "patches", "--frames", "20"]
    assert _run([*surrogate, "--spp", "1", "--steps", "10", "--out", str(s2r)]).returncode == 0
    return reference, run, s2r / "surrogate_input"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=10, help="trials per kill/writer class")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    classes: dict[str, list[dict]] = {}
    started, host = time.monotonic(), machine()  # the tree as it was when the run began
    with tempfile.TemporaryDirectory() as base:
        base = Path(base)
        os.environ["MINCAM_RENDER_PLAN_CACHE"] = str(base / "plans")
        reference, run, recording = _fixtures(base)
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
        except PermissionError as err:  # not root: no tmpfs
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
        t["used_corrupt_data"] for k in ("corruption", "recording_corruption") for t in classes[k]
    )
    result["machine"] = host
    result["wall_time_s"] = time.monotonic() - started
    path = REPO / "benchmarks" / "results" / "faults.json"
    path.write_text(strict_json.dumps(result, indent=2) + "\n")
    for name, s in result.items():
        if isinstance(s, dict) and "trials" in s:
            print(f"{name}: {s['survived']}/{s['trials']} survived, data lost {s['data_lost']}")
    print(f"silent uses of corrupt data: {result['silent_uses_of_corrupt_data']}")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
