# SPDX-License-Identifier: Apache-2.0
"""Optional dependencies fail with one install line that works for this install.

qpretarget is on no package index: from a clone, `pip install "qpretarget[plot]"` fails, the hint
must say `pip install -e "/path/to/checkout[plot]"`.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

import qpretarget
from qpretarget import errors
from qpretarget.errors import MissingDependencyError, install_hint, missing_dependency

PACKAGE_DIR = Path(qpretarget.__file__).resolve().parent


def test_hint_from_a_source_checkout_names_the_checkout() -> None:
    # The tests run from the repository, so the package's parent holds pyproject.toml.
    root = PACKAGE_DIR.parent
    assert (root / "pyproject.toml").is_file()
    assert errors.source_checkout() == root
    hint = install_hint("plot", "drawing figures")
    assert hint == f'drawing figures needs the `plot` extra: pip install -e "{root}[plot]"'


def test_hint_from_an_index_install(monkeypatch) -> None:
    monkeypatch.setattr(errors, "source_checkout", lambda: None)
    assert install_hint("viz", "the viewer") == (
        'the viewer needs the `viz` extra: pip install "qpretarget[viz]"'
    )


def test_missing_dependency_is_an_import_error_with_the_extra() -> None:
    exc = missing_dependency("mocap", "reading C3D files")
    assert isinstance(exc, ImportError) and isinstance(exc, errors.QPRetargetError)
    assert exc.extra == "mocap" and "[mocap]" in str(exc)


def test_every_hinted_extra_exists() -> None:
    # Every extra named by a hint in the package is an extra of pyproject.toml.
    import tomllib

    extras = tomllib.loads((PACKAGE_DIR.parent / "pyproject.toml").read_text())["project"][
        "optional-dependencies"
    ]
    used = set()
    for path in PACKAGE_DIR.rglob("*.py"):
        text = path.read_text()
        used |= set(re.findall(r"missing_dependency\(\s*\"(\w+)\"", text))
        used |= set(re.findall(r"install_hint\(\s*\"(\w+)\"", text))
    assert used, "no call site found"
    assert used <= set(extras), f"hints name unknown extras: {sorted(used - set(extras))}"


def test_no_hand_written_qpretarget_install_lines() -> None:
    # `pip install qpretarget[...]` written by hand is wrong from a clone: use install_hint.
    offenders = []
    for path in sorted(PACKAGE_DIR.rglob("*.py")):
        if path.name == "errors.py":  # install_hint itself, whose docstring shows both forms
            continue
        for n, line in enumerate(path.read_text().splitlines(), 1):
            if (
                re.search(r"pip install[^`\"']*[\"']?qpretarget\[", line)
                or 'pip install -e ".' in line
            ):
                offenders.append(f"{path.relative_to(PACKAGE_DIR.parent)}:{n}: {line.strip()}")
    assert not offenders, "use qpretarget.errors.install_hint:\n" + "\n".join(offenders)


def install_command(extra: str) -> str:
    """The command part of the hint, e.g. `pip install -e "/work/main[plot]"`."""
    return install_hint(extra, "x").split(": ", 1)[1]


def test_c3d_without_the_mocap_extra_gives_the_hint(monkeypatch, mocap_dir) -> None:
    from qpretarget.motion.load import load_motion

    monkeypatch.setitem(sys.modules, "c3d", None)  # `import c3d` -> ImportError
    with pytest.raises(MissingDependencyError) as info:
        load_motion(mocap_dir / "opensim_walking2.c3d")
    assert install_command("mocap") in str(info.value)


def test_plots_without_matplotlib_give_the_hint(monkeypatch) -> None:
    from qpretarget.analysis import plots

    for mod in list(sys.modules):
        if mod == "matplotlib" or mod.startswith("matplotlib."):
            monkeypatch.delitem(sys.modules, mod)
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    with pytest.raises(ImportError) as info:
        plots._figure(next(iter(plots.FIGSIZE)))
    assert install_command("plot") in str(info.value)


def test_renderer_without_matplotlib_gives_the_hint(monkeypatch) -> None:
    from qpretarget.viz import render

    monkeypatch.setitem(sys.modules, "matplotlib", None)
    with pytest.raises(MissingDependencyError) as info:
        render._require_plot()
    assert install_command("plot") in str(info.value)


def test_viewer_without_viser_gives_the_hint(monkeypatch) -> None:
    from qpretarget.viz import viewer

    monkeypatch.setitem(sys.modules, "viser", None)
    with pytest.raises(MissingDependencyError) as info:
        viewer._viser()
    assert install_command("viz") in str(info.value)
