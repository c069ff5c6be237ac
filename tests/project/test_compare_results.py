"""benchmarks/compare_results.py: before/after tables of a results JSON across git revisions."""

import json
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "compare_results.py"


def git(repo: Path, *args: str) -> str:
    return subprocess.run(
        ["git", "-C", str(repo), *args], check=True, capture_output=True, text=True
    ).stdout.strip()


def commit_json(repo: Path, data: object, message: str) -> str:
    (repo / "r.json").write_text(json.dumps(data))
    git(repo, "add", "r.json")
    git(repo, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", message)
    return git(repo, "rev-parse", "HEAD")


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, str(SCRIPT), *args], capture_output=True, text=True, check=False
    )


def make_repo(tmp_path: Path) -> tuple[Path, str, str]:
    repo = tmp_path / "repo"
    repo.mkdir()
    git(repo, "init", "-q")
    old = {
        "git_revision": "aaa",
        "results": [{"family": "patches", "w": 2.0, "ok": True}, {"family": "ws", "w": 4.0}],
        "seconds": 10,
        "gone": 1.0,
    }
    first = commit_json(repo, old, "one")
    new = {
        "git_revision": "bbb",
        "results": [{"family": "ws", "w": 5.0}, {"family": "patches", "w": 2.0, "ok": False}],
        "seconds": 0,
        "added": 3.0,
    }
    second = commit_json(repo, new, "two")
    return repo, first, second


def test_default_before_is_the_version_before_the_latest_change(tmp_path):
    repo, first, _ = make_repo(tmp_path)
    out_json = tmp_path / "table.json"
    done = run(str(repo / "r.json"), "--json", str(out_json))
    assert done.returncode == 0, done.stderr
    assert f"before {first[:9]} (measured at aaa)" in done.stdout
    assert "(measured at bbb)" in done.stdout
    # records matched by family, not by position; keys only on one side are left out
    assert "| results[family=ws].w | 4 | 5 | 1.25 |" in done.stdout
    assert "| results[family=patches].w | 2 | 2 | 1 |" in done.stdout
    assert "| results[family=patches].ok | True | False |  |" in done.stdout
    assert "| seconds | 10 | 0 | 0 |" in done.stdout
    assert "gone" not in done.stdout and "added" not in done.stdout
    table = json.loads(out_json.read_text())
    assert table["before"] == first
    assert {r["key"]: r["ratio"] for r in table["rows"]}["results[family=ws].w"] == 1.25


def test_match_and_uncommitted_change_compares_with_head(tmp_path):
    repo, _, second = make_repo(tmp_path)
    (repo / "r.json").write_text(json.dumps({"results": [{"family": "ws", "w": 10.0}]}))
    done = run(str(repo / "r.json"), "--match", r"\.w$")
    assert done.returncode == 0, done.stderr
    assert f"before {second[:9]}" in done.stdout
    assert done.stdout.strip().splitlines()[-1] == "| results[family=ws].w | 5 | 10 | 2 |"
    assert "1 rows" in done.stdout


def test_explicit_revisions_and_clear_errors(tmp_path):
    repo, first, second = make_repo(tmp_path)
    done = run(str(repo / "r.json"), "--before", second, "--after", first, "--match", "ws")
    assert "| results[family=ws].w | 5 | 4 | 0.8 |" in done.stdout
    bad = run(str(repo / "r.json"), "--before", "nosuchrev")
    assert bad.returncode == 1 and "nosuchrev" in bad.stderr and "Traceback" not in bad.stderr
    missing = run(str(repo / "none.json"))
    assert missing.returncode == 1 and "no such file" in missing.stderr
    fresh = tmp_path / "fresh"
    fresh.mkdir()
    git(fresh, "init", "-q")
    commit_json(fresh, {"a": 1}, "only")
    once = run(str(fresh / "r.json"))
    assert once.returncode == 1 and "no earlier committed version" in once.stderr
