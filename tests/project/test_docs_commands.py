"""Every command shown in README.md, docs/ and the commands' own examples exists as written.

Each command line is checked against the real click commands: the subcommand
exists, every option it uses is one of that command's options, and its
``--help`` works. Commands that would render or train are not run here (the
main job has its own tests); a renamed option or command fails this test.
"""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from mincam_render.cli.main import main

REPO = Path(__file__).resolve().parents[2]
DOCS = [
    REPO / "README.md",
    REPO / "masks" / "README.md",
    REPO / "examples" / "README.md",
    *sorted((REPO / "docs").glob("*.md")),
]
#: `mincam-render ...` up to the end of an inline code span or of a line
_PREFIXED = re.compile(r"mincam-render((?: [^`\n|]*)?)")
#: first cell of a row of the README's command table: | `render FAMILY --frames N` |
_TABLE_ROW = re.compile(r"^\| `([a-z][a-z0-9-]*(?: [^`]*)?)` \|", re.MULTILINE)


def _joined_lines(text: str) -> str:
    return re.sub(r"\\\n\s*", " ", text)


def _documented_commands() -> list[tuple[str, str]]:
    found = []
    for path in DOCS:
        text = _joined_lines(path.read_text())
        where = str(path.relative_to(REPO))
        found += [(where, m.group(1).strip()) for m in _PREFIXED.finditer(text)]
        table = _command_table(text)
        found += [(where, m.group(1).strip()) for m in _TABLE_ROW.finditer(table)]
    for name, command in _walk(main):
        text = _joined_lines(command.help or "")
        found += [(f"{name} --help", m.group(1).strip()) for m in _PREFIXED.finditer(text)]
    return [(w, c) for w, c in found if c]


def _command_table(text: str) -> str:
    """The "## Command line" section of a Markdown file, or ""."""
    start = text.find("\n## Command line")
    if start < 0:
        return ""
    end = text.find("\n## ", start + 1)
    return text[start : end if end > 0 else len(text)]


def _walk(group: click.Group, prefix: str = ""):
    for name, command in group.commands.items():
        yield prefix + name, command
        if isinstance(command, click.Group):
            yield from _walk(command, prefix + name + " ")


def _resolve(tokens: list[str]) -> tuple[list[str], click.Command]:
    path, command = [], main
    while isinstance(command, click.Group) and tokens and tokens[0] in command.commands:
        command = command.commands[tokens.pop(0)]
        path.append(command.name)
    return path, command


def _options(command: click.Command) -> set[str]:
    names = {"--help", "-h"}
    for param in command.params:
        if isinstance(param, click.Option):
            names.update(param.opts, param.secondary_opts)
    return names


COMMANDS = _documented_commands()


def test_the_docs_show_commands_at_all():
    """The parser finds the README's table and its examples (else the test below is empty)."""
    assert len(COMMANDS) >= 25, COMMANDS
    assert any(c.startswith("pipeline") for _, c in COMMANDS)


def _problems(line: str) -> list[str]:
    """What is wrong with ``mincam-render <line>`` against the real commands ([] if nothing)."""
    tokens = shlex.split(line.replace("[", "").replace("]", ""))
    path, command = _resolve(list(tokens))
    if not path:
        return [f"`{line}` names no command of mincam-render"]
    if isinstance(command, click.Group):
        return [f"`{line}` stops at the command group {path}"]
    known = _options(command)
    unknown = [
        t.split("=")[0] for t in tokens if t.startswith("-") and t.split("=")[0] not in known
    ]
    if unknown:
        return [f"`{line}`: {unknown} are not options of {' '.join(path)}"]
    res = CliRunner().invoke(main, [*path, "--help"])
    return [] if res.exit_code == 0 else [f"{' '.join(path)} --help failed: {res.output}"]


@pytest.mark.parametrize(
    "line",
    ["train DATASET --baseline-grid 8x8", "render-all patches", "bench", "preview --frame 3"],
)
def test_the_checker_catches_drifted_commands(line):
    """The drift the issue found (`train --baseline-grid`) and others are reported."""
    assert _problems(line)


@pytest.mark.parametrize(("where", "line"), COMMANDS, ids=[f"{w}: {c}" for w, c in COMMANDS])
def test_documented_command_exists_with_its_options(where, line):
    assert _problems(line) == [], where
