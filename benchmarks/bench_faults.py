"""Reliability under faults: repeated trials per fault class, what survived, what was lost.

Classes (each trial runs the real command line in a subprocess):

- ``render_kill``: `render` killed (SIGKILL of its process group) at a random moment, then
  resumed; survived = the resumed dataset is byte-identical to an uninterrupted one and no
  finished shard was rewritten. Data lost = finished shards rewritten.
- ``train_kill``: `train` killed at a random moment after its first checkpoint, then resumed;
  survived = it finishes all steps, the checkpoint was never torn and history.jsonl has each
  evaluation step exactly once. Data lost = checkpointed steps repeated. Each trial records
  whether the kill landed mid-run (the checkpoint's step below the total).
- ``corruption``: each damage kind x each reader (train, export-exr); survived = the reader
  refuses with exit 2 and one line naming the damaged file (never trains or exports from it).
- ``concurrent_writers``: two `render` commands into one directory at once; survived = one
  fails at once with the writer-lock message and the other's dataset verifies.

Not covered here: a full disk (tests/test_reliability.py fills a real loop-mounted tmpfs when
run as root; the benchmark machine may not allow it).

Usage:
    PYTHONPATH=. .venv/bin/python benchmarks/bench_faults.py [--trials 3]
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
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
RENDER = ["render", "patches", "--frames", "40", "--shard-frames", "8", "--detectors", "2"]
RENDER += ["--mask-res", "8", "--spp", "2", "--seed", "5", "--no-progress", "--workers", "0"]
TRAIN_STEPS = 3000  # about 6 s here: the kill lands mid-run, after the first checkpoint
TRAIN = ["--steps", str(TRAIN_STEPS), "--eval-every", "20", "--batch-size", "8"]
TRAIN += ["--patience", "1000"]
DAMAGE = ("missing-shard", "truncated-shard", "flipped-byte", "edited-manifest")


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
    shards = sorted((out / "shards").glob("shard-*.npy")) if (out / "shards").exists() else []
    before = {s.name: s.stat().st_mtime_ns for s in shards}
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


def _damage(root: Path, how: str) -> str:
    from mincam_render.data import dataset as ds

    npy, _ = ds.shard_paths(root, 1)
    if how == "missing-shard":
        npy.unlink()
        return npy.name
    if how == "truncated-shard":
        npy.write_bytes(npy.read_bytes()[:300])
        return npy.name
    if how == "flipped-byte":
        data = bytearray(npy.read_bytes())
        data[len(data) // 2] ^= 0x40
        npy.write_bytes(bytes(data))
        return npy.name
    manifest = json.loads((root / ds.MANIFEST_NAME).read_text())
    manifest["job"]["render"]["spp"] += 1
    (root / ds.MANIFEST_NAME).write_text(json.dumps(manifest))
    return ds.MANIFEST_NAME


def corruption(tmp: Path, dataset: Path, how: str, reader: str) -> dict:
    root = tmp / "damaged"
    shutil.copytree(dataset, root)
    name = _damage(root, how)
    out = tmp / "out"
    args = (
        ["train", str(root), "--out", str(out), "--steps", "4", "--eval-every", "2"]
        if reader == "train"
        else ["export-exr", str(root), "--frames", "0-39", "--out", str(out)]
    )
    done = _run(args)
    lines = [ln for ln in done.stderr.splitlines() if ln.startswith("Error:")]
    refused = done.returncode == 2 and len(lines) == 1 and name in lines[0]
    used = out.exists() and any(out.iterdir())
    return {"survived": refused and not used, "lost": 0, "damage": how, "reader": reader}


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


def _summary(trials: list[dict]) -> dict:
    return {
        "trials": len(trials),
        "killed_mid_run": sum(t.get("killed_mid_run", True) for t in trials),
        "survived": sum(t["survived"] for t in trials),
        "data_lost": sum(t["lost"] for t in trials),
        "details": trials,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=3, help="trials per kill/writer class")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    classes: dict[str, list[dict]] = {
        k: [] for k in ("render_kill", "train_kill", "corruption", "concurrent_writers")
    }
    with tempfile.TemporaryDirectory() as base:
        base = Path(base)
        os.environ["MINCAM_RENDER_PLAN_CACHE"] = str(base / "plans")
        reference = base / "reference"
        assert _run([*RENDER, "--out", str(reference)]).returncode == 0
        for i in range(args.trials):
            for name, trial in (
                ("render_kill", lambda t: render_kill(t, reference, rng)),
                ("train_kill", lambda t: train_kill(t, reference, rng)),
                ("concurrent_writers", concurrent_writers),
            ):
                tmp = Path(tempfile.mkdtemp(dir=base))
                classes[name].append(trial(tmp))
                print(name, i, classes[name][-1], flush=True)
        for how in DAMAGE:
            for reader in ("train", "export-exr"):
                tmp = Path(tempfile.mkdtemp(dir=base))
                classes["corruption"].append(corruption(tmp, reference, how, reader))
                print("corruption", classes["corruption"][-1], flush=True)
    result = {name: _summary(trials) for name, trials in classes.items()}
    path = REPO / "benchmarks" / "results" / "faults.json"
    path.write_text(json.dumps(result, indent=2) + "\n")
    for name, s in result.items():
        print(f"{name}: {s['survived']}/{s['trials']} survived, data lost {s['data_lost']}")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
