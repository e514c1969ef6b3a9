# SPDX-License-Identifier: Apache-2.0
"""The README's snippets run and its command table matches the command line.

The shell commands themselves (demo, retarget, evaluate, render, ...) are exercised by their own
tests; here: the Python and YAML examples run as written, every `qpretarget COMMAND` the README
names exists and its `--help` works, and every file path it names exists.
"""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

import pytest

import qpretarget
from qpretarget.cli import build_parser, main
from qpretarget.control.controller import Controller
from qpretarget.yamlio import load_yaml

ROOT = Path(qpretarget.__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text()


def blocks(lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", README, flags=re.S)


def test_python_snippets_run(monkeypatch, capsys) -> None:
    monkeypatch.chdir(ROOT)  # the snippets use paths relative to the checkout, as documented
    snippets = blocks("python")
    assert snippets
    for code in snippets:
        exec(compile(code, "README.md", "exec"), {})  # noqa: S102
    out = capsys.readouterr().out
    assert out.startswith("ok "), out


def test_yaml_example_builds_a_controller_and_steps() -> None:
    (example,) = blocks("yaml")
    ctrl = Controller(load_yaml(example))
    ctrl.reset()
    assert ctrl.step({}).status == "ok"


def readme_commands() -> list[str]:
    return sorted(set(re.findall(r"`qpretarget ([a-z][\w-]*)", README)))


def test_readme_commands_exist_and_have_help() -> None:
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    known = set(sub.choices)  # type: ignore[arg-type]
    named = readme_commands()
    assert set(named) - {"COMMAND"} <= known, set(named) - known
    # Every command of the CLI is in the README's table.
    table = set(re.findall(r"^\| `qpretarget ([\w-]+)", README, flags=re.M))
    assert table == known, f"README table {sorted(table)} != commands {sorted(known)}"


@pytest.mark.parametrize("command", readme_commands())
def test_readme_command_help(command: str) -> None:
    if command == "COMMAND":
        pytest.skip("placeholder")
    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit) as info:
        main([command, "--help"])
    assert info.value.code == 0
    assert "examples:" in out.getvalue()


def test_paths_in_readme_exist() -> None:
    paths = set(
        re.findall(
            r"(?<![\w/.])((?:configs|docs|scripts|tests|qpretarget)/[\w./{},*-]+[\w}*])", README
        )
    )
    paths |= set(re.findall(r"\]\(((?:docs)/[^)#]*)\)", README))
    missing = []
    for p in sorted(paths):
        if "{" in p or "*" in p:  # patterns such as configs/arm_*.yaml
            continue
        if not (ROOT / p).exists():
            missing.append(p)
    mocap = ROOT.parent / "shared" / "data" / "mocap"
    for name in re.findall(r"\.\./shared/data/mocap/([\w.-]+\.\w+)", README):
        if mocap.is_dir() and not (mocap / name).is_file():
            missing.append(f"../shared/data/mocap/{name}")
    assert not missing, missing
