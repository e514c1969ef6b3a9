# SPDX-License-Identifier: Apache-2.0
"""Controller YAML under bad input: wrong types, unknown keys, NaN/huge weights, syntax errors,
anchor bombs and ``!!python`` tags (which must never run code)."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import yaml

from qpretarget import Controller
from qpretarget.errors import ConfigError, SolverError

from .conftest import REPO, outcome

BASE = yaml.safe_load((REPO / "configs" / "g1_augmentation.yaml").read_text())


def _load(tmp_path, text: str):
    path = tmp_path / "c.yaml"
    path.write_text(text)
    return outcome(lambda: Controller.from_yaml(path))


def _mutated(fn) -> str:
    cfg = copy.deepcopy(BASE)
    fn(cfg)
    return yaml.safe_dump(cfg)


def _set(path, value):
    def fn(cfg):
        node = cfg
        for k in path[:-1]:
            node = node[k]
        node[path[-1]] = value

    return fn


CASES = {
    "dt string": _set(["dt"], "fast"),
    "dt zero": _set(["dt"], 0),
    "dt nan": _set(["dt"], float("nan")),
    "robot list": _set(["robot"], [1, 2]),
    "unknown robot": _set(["robot"], "g2"),
    "tasks mapping": _set(["tasks"], {"a": 1}),
    "task not mapping": _set(["tasks", 0], 42),
    "unknown task type": _set(["tasks", 0, "type"], "fram"),
    "unknown task key": _set(["tasks", 0, "wieght"], 1.0),
    "nan weight": _set(["tasks", 0, "position_weight"], float("nan")),
    "inf weight": _set(["tasks", 0, "position_weight"], float("inf")),
    "huge weight": _set(["tasks", 0, "position_weight"], 1e300),
    "negative weight": _set(["tasks", 0, "position_weight"], -1.0),
    "bool weight": _set(["tasks", 0, "position_weight"], True),
    "unknown frame": _set(["tasks", 0, "frame"], "no_such_link"),
    "unknown top key": _set(["strategyy"], "augmentation"),
    "strategy number": _set(["strategy"], 3),
    "solver unknown": _set(["solver"], "gurobi_"),
    "solver not installed": _set(["solver"], "gurobi"),
    "solver option": _set(["solver"], {"name": "daqp", "iter_limt": 10}),
    "fallback type": _set(["fallback"], "yes"),
    "constraints mapping": _set(["constraints"], {"type": "joint_limits"}),
    "constraint unknown key": _set(["constraints"], [{"type": "joint_limits", "gian": 0.9}]),
    "constraint nan gain": _set(["constraints"], [{"type": "joint_limits", "gain": float("nan")}]),
    "task weight string": _set(["tasks", 0, "position_weight"], "heavy"),
    "task weight list": _set(["tasks", 0, "position_weight"], [1.0, 2.0]),
    "huge dt": _set(["dt"], 1e300),
    "regularization nan": _set(["regularization"], {"type": "identity", "damping": float("nan")}),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_values_are_config_errors(tmp_path, case):
    kind, exc = _load(tmp_path, _mutated(CASES[case]))
    if case == "huge weight":  # legal, if silly: a valid controller or a clear error
        return
    if case == "solver not installed":  # a known solver missing here: says how to install it
        assert kind == "error" and isinstance(exc, SolverError), (case, exc)
        return
    assert kind == "error" and isinstance(exc, ConfigError), (case, exc)


@pytest.mark.parametrize(
    "text",
    [
        "robot: g1\ntasks: [\n",  # unclosed flow sequence
        "robot: g1\n  tasks: - a\n",  # bad indentation
        "\t robot: g1\n",  # tab
        "",  # empty file
        "- just\n- a\n- list\n",  # not a mapping
        "robot: g1\ntasks: *undefined_alias\n",
    ],
)
def test_syntax_errors_name_the_line(tmp_path, text):
    kind, exc = _load(tmp_path, text)
    assert kind == "error" and isinstance(exc, ConfigError)


def test_anchor_bomb_is_refused_quickly(tmp_path):
    bomb = "a: &a [x, x, x, x, x, x, x, x, x]\n"
    for i in range(1, 12):
        prev = chr(ord("a") + i - 1)
        cur = chr(ord("a") + i)
        bomb += f"{cur}: &{cur} [*{prev}, *{prev}, *{prev}, *{prev}, *{prev}, *{prev}]\n"
    kind, exc = _load(tmp_path, bomb + "robot: g1\n")
    assert kind == "error" and isinstance(exc, ConfigError)


@pytest.mark.parametrize(
    "tag",
    [
        "!!python/object/apply:os.system ['touch {marker}']",
        "!!python/object/new:os.system ['touch {marker}']",
        "!!python/name:os.system",
        "!!python/module:os",
        "!<tag:yaml.org,2002:python/object/apply:os.system> ['touch {marker}']",
    ],
)
@pytest.mark.parametrize("where", ["name", "task", "key"])
def test_python_tags_never_run_code(tmp_path, tag, where):
    """PyYAML's unsafe tags, at the top, inside a task and as a mapping key: refused, not run."""
    marker = tmp_path / "pwned"
    value = tag.format(marker=marker)
    if where == "name":
        text = f"robot: g1\nname: {value}\ntasks: [{{type: posture, weight: 1.0}}]\n"
    elif where == "task":
        text = f"robot: g1\ntasks:\n  - {{type: posture, weight: {value}}}\n"
    else:
        text = f"robot: g1\n? {value}\n: 1\ntasks: [{{type: posture, weight: 1.0}}]\n"
    kind, exc = _load(tmp_path, text)
    assert kind == "error" and isinstance(exc, ConfigError)
    assert not marker.exists()


def test_random_bytes_are_config_errors(tmp_path, rng):
    """Seeded garbage: binary noise and the real config with random bytes overwritten."""
    text = (REPO / "configs" / "g1_augmentation.yaml").read_bytes()
    for k in range(8):
        data = bytearray(text)
        for i in rng.integers(0, len(data), size=6):
            data[i] = int(rng.integers(0, 256))
        path = tmp_path / f"r{k}.yaml"
        path.write_bytes(bytes(data))
        outcome(lambda p=path: Controller.from_yaml(p))  # a controller or a documented error
    path = tmp_path / "noise.yaml"
    path.write_bytes(rng.integers(0, 256, size=2048, dtype=np.uint8).tobytes())
    kind, exc = outcome(lambda: Controller.from_yaml(path))
    assert kind == "error" and isinstance(exc, ConfigError)
