"""Before/after table of a results JSON: its numbers at a git revision against now.

Usage:
    python benchmarks/compare_results.py benchmarks/results/stability.json
        [--before REV] [--after REV] [--match REGEX] [--json OUT]

``--before`` defaults to the version the file had before its latest change: HEAD
when the working file differs from HEAD, else the parent of the last commit that
changed it. ``--after`` defaults to the working file. Every numeric (and boolean)
leaf present in both versions is a row: its key path, before, after and
after/before. Records in lists are keyed by their ``name``, ``family``, ``case``,
``job``, ``label`` or ``kind`` field where they have one (``#i`` tells repeats
apart), else by index. Prints a markdown table; ``--json`` also writes the rows.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from mincam_render.core import strict_json

ID_FIELDS = ("name", "family", "case", "job", "label", "kind")
REVISION_FIELDS = ("git_revision", "revision")


def git(repo: Path, *args: str) -> str:
    """Stdout of a git command run in ``repo``; a clear error if git refuses."""
    done = subprocess.run(["git", "-C", str(repo), *args], capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"git {' '.join(args)}: {done.stderr.strip()}")
    return done.stdout


def default_before(path: Path) -> str:
    """The revision holding the file's version before its latest change."""
    repo = path.resolve().parent
    name = path.resolve().name
    if git(repo, "status", "--porcelain", "--", name).strip():
        return git(repo, "rev-parse", "HEAD").strip()
    revisions = git(repo, "log", "--format=%H", "--", name).split()
    if len(revisions) < 2:
        raise SystemExit(f"{path}: no earlier committed version to compare with (give --before)")
    return revisions[1]


def load(path: Path, revision: str | None) -> Any:
    """The JSON at ``revision`` (``git show``) or, with None, the working file."""
    if revision is None:
        return json.loads(path.read_text())
    repo = path.resolve().parent
    top = Path(git(repo, "rev-parse", "--show-toplevel").strip())
    relative = path.resolve().relative_to(top).as_posix()
    return json.loads(git(top, "show", f"{revision}:{relative}"))


def record_keys(items: list[Any]) -> list[str]:
    """One key per list element: its identifying field's value, else its index."""
    keys = []
    for i, item in enumerate(items):
        field = next((f for f in ID_FIELDS if isinstance(item, dict) and item.get(f)), None)
        key = f"{field}={item[field]}" if field else str(i)
        keys.append(key if key not in keys else f"{key}#{i}")
    return keys


def leaves(node: Any, prefix: str = "") -> Iterator[tuple[str, float | bool]]:
    """(key path, value) of every numeric or boolean leaf."""
    if isinstance(node, dict):
        for key, value in node.items():
            yield from leaves(value, f"{prefix}.{key}" if prefix else str(key))
    elif isinstance(node, list):
        for key, value in zip(record_keys(node), node, strict=True):
            yield from leaves(value, f"{prefix}[{key}]")
    elif isinstance(node, bool | int | float):
        yield prefix, node


def recorded_revision(data: Any) -> str:
    """The git revision a results file says it was measured at ("?" if none)."""
    if isinstance(data, dict):
        for field in REVISION_FIELDS:
            if isinstance(data.get(field), str):
                return str(data[field])[:9]
        for value in data.values():
            found = recorded_revision(value)
            if found != "?":
                return found
    return "?"


def compare(before: Any, after: Any, pattern: str = "") -> list[dict[str, Any]]:
    """Rows (key, before, after, ratio) of the leaves in both, keys matching ``pattern``."""
    old = dict(leaves(before))
    rows = []
    for key, new in leaves(after):
        if key not in old or (pattern and not re.search(pattern, key)):
            continue
        numeric = not isinstance(new, bool) and not isinstance(old[key], bool)
        ratio = new / old[key] if numeric and old[key] != 0 else None
        rows.append({"key": key, "before": old[key], "after": new, "ratio": ratio})
    return rows


def cell(value: float | bool | None) -> str:
    if value is None:
        return ""
    return str(value) if isinstance(value, bool) else f"{value:.4g}"


def markdown(rows: list[dict[str, Any]]) -> str:
    lines = ["| key | before | after | after/before |", "|---|---:|---:|---:|"]
    for r in rows:
        lines.append(
            f"| {r['key']} | {cell(r['before'])} | {cell(r['after'])} | {cell(r['ratio'])} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("path", type=Path)
    ap.add_argument("--before", help="git revision of the old version")
    ap.add_argument("--after", help="git revision of the new version (default: the file)")
    ap.add_argument("--match", default="", help="only keys matching this regular expression")
    ap.add_argument("--json", type=Path, help="also write the rows to this JSON file")
    args = ap.parse_args(argv)
    if not args.path.is_file():
        raise SystemExit(f"{args.path}: no such file")
    before_rev = args.before or default_before(args.path)
    before, after = load(args.path, before_rev), load(args.path, args.after)
    rows = compare(before, after, args.match)
    print(
        f"{args.path}: before {before_rev[:9]} (measured at {recorded_revision(before)}), "
        f"after {args.after or 'working file'} (measured at {recorded_revision(after)}); "
        f"{len(rows)} rows"
    )
    print(markdown(rows))
    if args.json:
        table = {"path": str(args.path), "before": before_rev, "after": args.after, "rows": rows}
        args.json.write_text(strict_json.dumps(table, indent=1) + "\n")


if __name__ == "__main__":
    sys.exit(main())
