# SPDX-License-Identifier: Apache-2.0
"""The docs match the code.

* docs/yaml.md lists exactly the types and keys the registries accept, with their defaults
  (from ``qpretarget.schema.options()`` when it exists, else from the registries and the
  constructors' signatures, as ``qpretarget.registry.check_keywords`` reads them);
* every task and constraint option documented there changes the robot's motion: a G1 controller
  (configs/g1_augmentation.yaml) is run for 20 ticks of scripted targets with the key at its
  default and at another valid value, and the final configurations must differ. Keys that by
  design do not change the motion are listed in ``NO_EFFECT`` with the reason;
* module paths, imports and mocap files named in docs/ and README.md exist.
"""

from __future__ import annotations

import copy
import importlib
import inspect
import json
import re
from collections.abc import Mapping
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

import qpretarget
from qpretarget.analysis.solver_comparison import scripted_targets
from qpretarget.control.controller import Controller
from qpretarget.yamlio import load_yaml

ROOT = Path(qpretarget.__file__).resolve().parent.parent
YAML_MD = ROOT / "docs" / "yaml.md"
SECTIONS = {  # heading of docs/yaml.md -> section of qpretarget.schema.options()
    "Tasks": "tasks",
    "Constraints": "constraints",
    "Strategy": "strategy",
    "Regularization": "regularization",
    "Solver": "solver",
}
REQUIRED = object()


# ------------------------------------------------------------------------------ parsing the doc
def documented() -> dict[str, dict[str, dict[str, str]]]:
    """section -> type -> key -> documented default (the cell text), from docs/yaml.md."""
    out: dict[str, dict[str, dict[str, str]]] = {}
    section = kind = None
    for line in YAML_MD.read_text().splitlines():
        if line.startswith("## "):
            section = SECTIONS.get(line[3:].strip())
            kind = None
            if section:
                out[section] = {}
        elif line.startswith("### ") and section:
            m = re.fullmatch(r"### `(\w+)`", line.strip())
            assert m, f"docs/yaml.md: a type heading must be ### `name`: {line!r}"
            kind = m.group(1)
            out[section][kind] = {}
        elif section and kind and line.startswith("| `"):
            cells = [c.strip() for c in re.split(r"(?<!\\)\|", line.strip())[1:-1]]
            key = cells[0].strip("`")
            assert key not in out[section][kind], f"{section}.{kind}.{key} documented twice"
            out[section][kind][key] = cells[1]
    return out


def top_level_documented() -> set[str]:
    text = YAML_MD.read_text().split("## Top level", 1)[1].split("\n## ", 1)[0]
    return set(re.findall(r"^\| `(\w+)` \|", text, flags=re.M))


# ------------------------------------------------------------------------------ the code's view
def _signature_options(cls: type) -> dict[str, Any]:
    sig = inspect.signature(cls.__init__)  # type: ignore[misc]
    return {
        n: (REQUIRED if p.default is inspect.Parameter.empty else p.default)
        for n, p in sig.parameters.items()
        if n != "self" and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
    }


@cache
def accepted() -> dict[str, dict[str, dict[str, Any]]]:
    """section -> type -> key -> default (``REQUIRED`` when there is none)."""
    from qpretarget.constraints import CONSTRAINTS
    from qpretarget.solvers.daqp_ import DaqpSolver
    from qpretarget.solvers.proxsuite_ import ProxSuiteSolver
    from qpretarget.strategies import STRATEGIES
    from qpretarget.tasks import TASKS
    from qpretarget.weighting import REGULARIZATIONS

    registries = {
        "tasks": TASKS,
        "constraints": CONSTRAINTS,
        "strategy": STRATEGIES,
        "regularization": REGULARIZATIONS,
    }
    out = {s: {t: _signature_options(c) for t, c in r.items()} for s, r in registries.items()}
    out["solver"] = {}
    for cls in (ProxSuiteSolver, DaqpSolver):
        sig = _signature_options(cls)
        out["solver"][cls.name] = {k: sig[k] for k in cls.OPTIONS}
    try:
        from qpretarget.schema import options  # type: ignore[import-not-found, unused-ignore]
    except ImportError:
        return out
    # The schema is the reference for the keys; defaults still come from the signatures.
    schema = options()
    return {
        section: {
            kind: {k: out.get(section, {}).get(kind, {}).get(k, None) for k in keys}
            for kind, keys in schema[section].items()
        }
        for section in SECTIONS.values()
        if section in schema
    }


def test_yaml_md_documents_every_type_and_key() -> None:
    doc, code = documented(), accepted()
    assert set(doc) == set(SECTIONS.values())
    for section in SECTIONS.values():
        assert set(doc[section]) == set(code[section]), (
            f"{section}: documented types {sorted(doc[section])} != accepted {sorted(code[section])}"
        )
        for kind, keys in code[section].items():
            assert set(doc[section][kind]) == set(keys), (
                f"{section}.{kind}: documented {sorted(doc[section][kind])}, "
                f"accepted {sorted(keys)}"
            )


def _same_default(cell: str, default: Any) -> bool:
    if default is REQUIRED:
        return cell == "required"
    m = re.fullmatch(r"`([^`]*)`", cell)
    if not m:
        return False
    value = load_yaml(m.group(1))  # YAML 1.2 numbers, as the config reader
    if isinstance(default, tuple):
        default = list(default)
    if isinstance(default, float) and isinstance(value, int | float):
        return abs(value - default) <= 1e-12 * max(1.0, abs(default))
    return value == default


def test_yaml_md_defaults_match_the_constructors() -> None:
    doc, code = documented(), accepted()
    wrong = [
        f"{section}.{kind}.{key}: documented {doc[section][kind][key]}, code {default!r}"
        for section, kinds in code.items()
        for kind, keys in kinds.items()
        for key, default in keys.items()
        if default is not None or doc[section][kind][key] not in ("`null`",)
        if not _same_default(doc[section][kind][key], default)
    ]
    assert not wrong, "\n".join(wrong)


def test_yaml_md_top_level_keys() -> None:
    from qpretarget.control import controller

    # `viewer` was accepted and ignored; it is being removed from the schema (issue 21) and is
    # deliberately not documented.
    accepted_keys = set(controller.TOP_LEVEL_KEYS) - {"viewer"}
    assert top_level_documented() == accepted_keys


# ------------------------------------------------------------------------------ option effects
BASE_CONFIG = ROOT / "configs" / "g1_augmentation.yaml"
TICKS = 20
G1_ARM = ["left_shoulder_roll_link", "left_elbow_link", "left_wrist_pitch_link", "left_rubber_hand"]
ARM_SOURCE = np.array([[0.0, 0.0, 0.0], [0.25, 0.05, -0.05], [0.45, 0.1, 0.05], [0.5, 0.1, 0.1]])
COLLISION_PAIRS = [
    ["left_wrist_yaw_link", "pelvis_contour_link"],
    ["left_wrist_yaw_link", "left_hip_yaw_link"],
    ["left_elbow_link", "torso_link"],
    ["left_wrist_yaw_link", "torso_link"],
    ["right_wrist_yaw_link", "pelvis_contour_link"],
    ["right_wrist_yaw_link", "right_hip_yaw_link"],
]
OBSTACLE = {"name": "ball", "shape": "sphere", "radius": 0.05, "position": [0.08, 0.2, 0.78]}

#: (section, type) -> how the option tests place the module in the base controller:
#: ``replace`` names the task of configs/g1_augmentation.yaml it replaces, else it is added.
PROBES: dict[tuple[str, str], dict[str, Any]] = {
    ("tasks", "frame"): {
        "entry": {"type": "frame", "name": "left_hand", "frame": "left_rubber_hand",
                  "mode": "position", "position_weight": 100.0},
        "replace": "left_hand",
    },
    ("tasks", "com"): {"entry": {"type": "com", "name": "com", "weight": 10.0}},
    ("tasks", "posture"): {
        "entry": {"type": "posture", "name": "posture", "weight": 1.0e-3}, "replace": "posture",
    },
    ("tasks", "damping"): {"entry": {"type": "damping", "name": "damping", "weight": 1.0e-3}},
    ("tasks", "chain_shape"): {
        "entry": {"type": "chain_shape", "name": "arm", "frames": G1_ARM,
                  "reference_frame": "torso_link", "weight": 10.0},
        "target": ARM_SOURCE,
    },
    ("constraints", "joint_limits"): {
        "entry": {"type": "joint_limits", "gain": 0.95}, "replace": "joint_limits",
    },
    ("constraints", "velocity_limits"): {
        "entry": {"type": "velocity_limits"}, "replace": "velocity_limits",
    },
    ("constraints", "acceleration_limits"): {"entry": {"type": "acceleration_limits",
                                                       "a_max": 300.0}},
    ("constraints", "contacts"): {"entry": {"type": "contacts"}},
    ("constraints", "support_polygon"): {
        "entry": {"type": "support_polygon", "margin": 0.08}, "with": [{"type": "contacts"}],
    },
    ("constraints", "self_collision"): {
        "entry": {"type": "self_collision", "pairs": COLLISION_PAIRS, "d_s": 0.1, "d_i": 0.25},
    },
    ("constraints", "ground"): {
        "entry": {"type": "ground", "links": [], "obstacles": [OBSTACLE], "d_i": 0.3,
                  "obstacle_links": ["left_wrist_yaw_link", "left_elbow_link",
                                     "left_rubber_hand"]},
    },
    # Both feet lifted (no contact in force), the floor 10 cm above the soles: pushed up.
    ("constraints", "sole_ground"): {
        "entry": {"type": "sole_ground", "height": 0.1},
        "with": [{"type": "contacts", "active": []}],
    },
}  # fmt: skip

HIERARCHY = {"strategy": {"type": "hierarchy"}}
#: The pelvis above a raised ground, with a slow damper: the pelvis dips up to 3 cm in the run.
PELVIS_GROUND = {"links": ["pelvis_contour_link"], "gain_per_tick": 0.01, "obstacles": None,
                 "obstacle_links": None}  # fmt: skip
AUTO_PAIRS = {"pairs": "auto", "links": ["left_wrist_yaw_link", "left_elbow_link", "torso_link",
                                         "pelvis_contour_link", "left_hip_yaw_link"]}  # fmt: skip

#: (section, type, key) -> (context, new value). The context changes the probe (``entry``), the
#: top level (``config``) or blanks the probe's target at tick 5 (``missing``) so the key has
#: something to act on; the base run has the context with the key at its default.
CHANGES: dict[tuple[str, str, str], tuple[dict[str, Any], Any]] = {
    ("tasks", "frame", "frame"): ({}, "left_elbow_link"),
    ("tasks", "frame", "mode"): ({}, "pose"),
    ("tasks", "frame", "position_weight"): ({}, 0.01),
    ("tasks", "frame", "orientation_weight"): ({"entry": {"mode": "pose"}}, 0.01),
    ("tasks", "frame", "offset"): ({}, [0.05, 0.0, 0.0]),
    ("tasks", "frame", "weight"): ({}, 0.01),
    ("tasks", "frame", "gain"): ({}, 5.0),
    ("tasks", "frame", "level"): ({"config": HIERARCHY}, 2),
    ("tasks", "frame", "feedforward"): ({"entry": {"gain": 5.0}}, True),
    ("tasks", "frame", "recovery_time"): ({"missing": True}, 0.0),
    ("tasks", "com", "axes"): ({}, "xy"),
    ("tasks", "com", "weight"): ({}, 0.1),
    ("tasks", "com", "gain"): ({}, 5.0),
    ("tasks", "com", "level"): ({"config": HIERARCHY}, 2),
    ("tasks", "com", "feedforward"): ({"entry": {"gain": 5.0}, "moving": True}, True),
    ("tasks", "com", "recovery_time"): ({"missing": True}, 0.0),
    ("tasks", "posture", "weight"): ({}, 1.0),
    ("tasks", "posture", "default_weight"): ({"entry": {"weight": {"left_elbow_joint": 1.0}}}, 1e-3),
    ("tasks", "posture", "gain"): ({}, 5.0),
    ("tasks", "posture", "level"): ({"config": HIERARCHY}, 2),
    ("tasks", "posture", "recovery_time"): ({"missing": True}, 0.0),
    ("tasks", "damping", "weight"): ({}, 1.0),
    ("tasks", "damping", "level"): ({"config": HIERARCHY}, 2),
    ("tasks", "chain_shape", "frames"): ({}, G1_ARM[:3]),
    ("tasks", "chain_shape", "n_samples"): ({}, 5),
    ("tasks", "chain_shape", "alpha"): ({}, 5.0),
    ("tasks", "chain_shape", "reference_frame"): ({}, "pelvis"),
    ("tasks", "chain_shape", "source_rotation"): ({}, [0.0, 0.0, 0.5]),
    ("tasks", "chain_shape", "weight"): ({}, 0.1),
    ("tasks", "chain_shape", "gain"): ({}, 5.0),
    ("tasks", "chain_shape", "level"): ({"config": HIERARCHY}, 2),
    ("tasks", "chain_shape", "recovery_time"): ({"missing": True}, 0.0),
    ("constraints", "joint_limits", "gain"): ({"entry": {"margin": 0.3}}, 0.3),
    ("constraints", "joint_limits", "margin"): ({}, 0.3),
    ("constraints", "velocity_limits", "scale"): ({}, 0.05),
    ("constraints", "acceleration_limits", "a_max"): ({}, 20.0),
    ("constraints", "acceleration_limits", "braking"): ({"entry": {"a_max": 100.0}}, False),
    ("constraints", "acceleration_limits", "base"): ({}, [1.0, 5.0]),
    ("constraints", "contacts", "feet"): ({}, ["left_foot"]),
    ("constraints", "contacts", "frames"): ({}, {"left_sole": "left_ankle_roll_link"}),
    ("constraints", "contacts", "active"): ({}, ["left_foot"]),
    ("constraints", "contacts", "gain"): ({}, 5.0),
    ("constraints", "contacts", "second_order"): ({}, False),
    ("constraints", "contacts", "max_correction"): ({}, [1e-4, 1e-4]),
    ("constraints", "contacts", "refine"): ({}, False),
    ("constraints", "contacts", "refine_tolerance"): ({}, 1e-2),
    ("constraints", "contacts", "refine_iterations"): ({}, 1),
    ("constraints", "support_polygon", "margin"): ({}, 0.02),
    ("constraints", "support_polygon", "gain"): ({}, 0.9),
    # A recovery the box can follow (0.084 asked for more: at capacity both depths gave the
    # same motion once the polygon rows became soft).
    ("constraints", "support_polygon", "recovery_depth"): (
        {"entry": {"margin": 0.083, "gain": 0.05}}, 0.03),
    ("constraints", "support_polygon", "second_order"): ({}, False),
    ("constraints", "self_collision", "pairs"): ({}, COLLISION_PAIRS[:2]),
    ("constraints", "self_collision", "d_s"): ({}, 0.05),
    ("constraints", "self_collision", "d_i"): ({}, 0.15),
    ("constraints", "self_collision", "xi"): ({}, 0.05),
    ("constraints", "self_collision", "gain"): ({}, 2.0),
    ("constraints", "self_collision", "gain_per_tick"): ({}, 0.05),
    ("constraints", "self_collision", "recovery_speed"): ({"entry": {"d_s": 0.2}}, 0.05),
    ("constraints", "self_collision", "geometry"): ({}, "capsule"),
    ("constraints", "self_collision", "links"): ({"entry": AUTO_PAIRS}, ["left_wrist_yaw_link",
                                                                         "pelvis_contour_link"]),
    ("constraints", "self_collision", "exclude"): ({}, COLLISION_PAIRS[:3]),
    ("constraints", "self_collision", "include"): (
        {"entry": {"pairs": "auto"}}, [["torso_link", "left_shoulder_roll_link"],
                                       ["left_wrist_roll_link", "left_wrist_yaw_link"]]),
    ("constraints", "self_collision", "rest_fraction"): ({"entry": AUTO_PAIRS}, 1.0),
    ("constraints", "self_collision", "safety"): ({}, [[*p, 0.01] for p in COLLISION_PAIRS]),
    ("constraints", "self_collision", "trust_gap_fraction"): ({"entry": AUTO_PAIRS}, 0.0),
    ("constraints", "self_collision", "touch_distance"): (
        {"entry": {**AUTO_PAIRS, "d_s": 0.02, "d_i": 0.1}}, 0.1),
    ("constraints", "self_collision", "max_rows"): ({}, 1),
    ("constraints", "self_collision", "trust_region"): ({}, None),
    ("constraints", "self_collision", "hull_vertices"): ({}, 8),
    ("constraints", "ground", "links"): (
        {"entry": {"height": 0.62, "gain_per_tick": 0.01}}, ["pelvis_contour_link"]),
    ("constraints", "ground", "height"): ({"entry": PELVIS_GROUND}, 0.62),
    ("constraints", "ground", "margin"): ({"entry": {**PELVIS_GROUND, "height": 0.6}}, 0.05),
    ("constraints", "ground", "arm_height"): ({"entry": {**PELVIS_GROUND, "height": 0.62}}, 0.2),
    ("constraints", "ground", "obstacles"): ({}, [{**OBSTACLE, "radius": 0.08}]),
    ("constraints", "ground", "obstacle_links"): ({}, ["left_elbow_link"]),
    ("constraints", "ground", "obstacle_margin"): ({}, 0.05),
    ("constraints", "ground", "d_i"): ({"entry": {"xi": 0.05}}, 0.1),
    ("constraints", "ground", "xi"): ({}, 0.05),
    ("constraints", "ground", "gain"): ({}, 2.0),
    ("constraints", "ground", "gain_per_tick"): ({}, 0.05),
    ("constraints", "ground", "recovery_speed"): ({"entry": {"obstacle_margin": 0.2}}, 0.05),
    ("constraints", "ground", "geometry"): ({}, "capsule"),
    ("constraints", "ground", "max_rows"): ({"entry": {"obstacle_links": None}}, 1),
    ("constraints", "ground", "trust_region"): ({}, None),
    ("constraints", "ground", "trust_gap_fraction"): ({}, 1.0),
    ("constraints", "ground", "hull_vertices"): ({}, 8),
    ("constraints", "sole_ground", "feet"): ({}, ["left_foot"]),
    ("constraints", "sole_ground", "height"): ({}, 0.01),
    ("constraints", "sole_ground", "gain_per_tick"): ({}, 0.1),
    ("constraints", "sole_ground", "recovery_speed"): ({}, 0.05),
    ("constraints", "sole_ground", "d_i"): ({"entry": {"height": 0.0, "gain_per_tick": 0.01}},
                                           0.001),
    # The floor just under the soles (0.5 mm, no contact): first order lets a corner come down
    # 5 cm/s in a tick, the braking bound sqrt(2 a z) at 1 m/s^2 only 3 cm/s.
    ("constraints", "sole_ground", "brake_accel"): ({"entry": {"height": -0.0005}}, 1.0),
}  # fmt: skip

#: Documented task and constraint keys that do not change the motion, and why.
NO_EFFECT: dict[tuple[str, str, str], str] = {
    **{("tasks", t, "name"): "the key of the target in step(), not a parameter of the motion"
       for t in ("frame", "com", "posture", "damping", "chain_shape")},
    **{("constraints", c, "name"): "a label for messages and StepResult.relaxed"
       for c in ("joint_limits", "velocity_limits", "acceleration_limits", "contacts",
                 "support_polygon", "self_collision", "ground", "sole_ground")},
    ("constraints", "self_collision", "broad_phase"): "conservative: it only skips pairs that "
    "provably stay beyond d_i, so the rows and the result are the same (faster)",
    ("constraints", "ground", "broad_phase"): "conservative: same rows, same result (faster)",
    ("constraints", "ground", "plane_trust"): "loosens the trust-region box only; the scripted "
    "motion's ground rows never reach it (its effect: tests/constraints/test_ground.py, "
    "test_kernel.py and the seven clips in docs/retargeting.md)",
    ("constraints", "support_polygon", "max_edges"): "rows reserved for the polygon's edges: any "
    "value that fits the hull gives the same polygon (a smaller one is a ConfigError)",
    ("constraints", "self_collision", "use_srdf"): "G1 ships no SRDF, so there are no disabled "
    "pairs to leave out (Talos/Romeo/iCub have some)",
    ("constraints", "self_collision", "optional"): "G1 has collision geometry: it only matters on "
    "a robot without (tests/constraints/test_self_collision.py)",
}  # fmt: skip

#: Documented keys that should change the motion but do not (a bug to fix in the code): the test
#: expects the failure so that fixing it makes the test (and these docs) be revisited.
KNOWN_NO_EFFECT: dict[tuple[str, str, str], str] = {}


def option_cases() -> list[tuple[str, str, str]]:
    doc = documented()
    return [
        (section, kind, key)
        for section in ("tasks", "constraints")
        for kind, keys in sorted(doc[section].items())
        for key in keys
    ]


def test_every_documented_option_has_an_effect_case() -> None:
    missing = [c for c in option_cases() if c not in CHANGES and c not in NO_EFFECT
               and c not in KNOWN_NO_EFFECT]  # fmt: skip
    assert not missing, f"add these to CHANGES (or NO_EFFECT with the reason): {missing}"
    stale = [c for c in [*CHANGES, *NO_EFFECT, *KNOWN_NO_EFFECT] if c not in option_cases()]
    assert not stale, f"not documented in docs/yaml.md: {stale}"


@cache
def base_config() -> dict[str, Any]:
    cfg = yaml.safe_load(BASE_CONFIG.read_text())
    cfg.pop("retarget", None)
    return cfg


@cache
def scripted() -> tuple[dict[str, Any], ...]:
    # The last TICKS ticks of 1.2 s of scripted targets: the first target is far from the
    # standing robot, so limits, dampers and gains all have something to act on.
    ctrl = Controller(copy.deepcopy(base_config()))
    return tuple(list(scripted_targets(ctrl, 1.2))[-TICKS:])


def build_config(section: str, kind: str, context: Mapping[str, Any], change: Mapping[str, Any]):
    probe = PROBES[(section, kind)]
    cfg = copy.deepcopy(base_config())
    cfg.update(copy.deepcopy(dict(context.get("config", {}))))
    entry = {**probe["entry"], **context.get("entry", {}), **change}
    items = cfg.setdefault(section, [])
    replace = probe.get("replace")
    if replace is not None:
        idx = next(i for i, e in enumerate(items) if e.get("name", e["type"]) == replace)
        items[idx] = entry
    else:
        items.extend(copy.deepcopy(probe.get("with", [])))
        items.append(entry)
    return cfg


@cache
def _final_q(
    cfg_json: str, target_name: str | None, missing: bool, moving: bool = False
) -> np.ndarray:
    cfg = json.loads(cfg_json)
    ctrl = Controller(cfg)
    ctrl.reset()
    res = None
    probe_target = None
    com0 = ctrl.state.com().copy()
    for k, targets in enumerate(scripted()):
        targets = dict(targets)
        if moving and target_name is not None:  # a CoM target moving at 0.1 m/s along x
            targets[target_name] = com0 + np.array([0.001 * k, 0.0, 0.0])
        elif target_name is not None:
            task = ctrl.tasks[target_name]
            if target_name == "arm":
                probe_target = ARM_SOURCE
            if probe_target is not None:
                targets[target_name] = probe_target
            if missing and k == 5:
                shape = (
                    np.shape(probe_target)
                    if probe_target is not None
                    else ((ctrl.robot.nq,) if type(task).type_name == "posture" else (3,))
                )
                targets[target_name] = np.full(shape, np.nan)
        res = ctrl.step(targets)
    assert res is not None
    return np.asarray(res.q, float)


def final_q(
    cfg: Mapping[str, Any], target_name: str | None, missing: bool, moving: bool = False
) -> np.ndarray:
    return _final_q(json.dumps(cfg, sort_keys=True, default=_json), target_name, missing, moving)


def _json(x: Any) -> Any:
    if isinstance(x, np.ndarray):
        return x.tolist()
    raise TypeError(type(x))


def _effect(section: str, kind: str, key: str, context: Mapping[str, Any], value: Any) -> float:
    probe = PROBES[(section, kind)]
    target_name = probe["entry"].get("name") if section == "tasks" else None
    missing = bool(context.get("missing"))
    moving = bool(context.get("moving"))
    base = build_config(section, kind, context, {})
    changed = build_config(section, kind, context, {key: value})
    q0 = final_q(base, target_name, missing, moving)
    q1 = final_q(changed, target_name, missing, moving)
    return float(np.abs(q1 - q0).max())


@pytest.mark.parametrize(
    "case",
    [pytest.param(c, id=".".join(c)) for c in CHANGES]
    + [
        pytest.param(c, id=".".join(c), marks=pytest.mark.xfail(reason=r, strict=True))
        for c, r in KNOWN_NO_EFFECT.items()
    ],
)
def test_documented_option_changes_the_motion(case: tuple[str, str, str]) -> None:
    section, kind, key = case
    if case in KNOWN_NO_EFFECT:
        context, value = {}, True
    else:
        context, value = CHANGES[case]
    # 1e-9 rad: far above the solver's reproducibility (runs from reset() are bitwise equal).
    assert _effect(section, kind, key, context, value) > 1e-9, (
        f"{section}.{kind}.{key}: changing it to {value!r} does not change the motion"
    )


# ------------------------------------------------------------------------------ names in the docs
def doc_files() -> list[Path]:
    # docs/architecture.md is written at the end of the refactoring (excluded until then).
    return [ROOT / "README.md"] + sorted(
        p for p in (ROOT / "docs").rglob("*.md") if p.name != "architecture.md"
    )


def _rel(p: Path) -> str:
    return str(p.relative_to(ROOT))


def test_module_paths_in_docs_exist() -> None:
    wrong = []
    for doc in doc_files():
        for m in re.finditer(r"qpretarget/[\w/]+\.(?:py|yaml)", doc.read_text()):
            if not (ROOT / m.group(0)).exists():
                wrong.append(f"{_rel(doc)}: {m.group(0)}")
    assert not wrong, "\n".join(wrong)


def test_python_names_in_docs_resolve() -> None:
    wrong = []
    for doc in doc_files():
        text = doc.read_text()
        for m in re.finditer(r"from (qpretarget[\w.]*) import (\([^)]*\)|[^\n]+)", text):
            module = m.group(1)
            try:
                mod = importlib.import_module(module)
            except ImportError as exc:
                wrong.append(f"{_rel(doc)}: from {module}: {exc}")
                continue
            for name in re.split(r"[,\s]+", re.sub(r"#.*", "", m.group(2)).strip("() \n")):
                if name and not hasattr(mod, name):
                    wrong.append(f"{_rel(doc)}: {module} has no {name}")
        for m in re.finditer(r"`(qpretarget(?:\.\w+)+)(?![\w/])", text):
            if not _resolves(m.group(1)):
                wrong.append(f"{_rel(doc)}: {m.group(1)}")
    assert not wrong, "\n".join(wrong)


def _resolves(dotted: str) -> bool:
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj: Any = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for attr in parts[i:]:
            if not hasattr(obj, attr):
                return False
            obj = getattr(obj, attr)
        return True
    return False


def test_mocap_files_named_in_docs_exist() -> None:
    mocap = ROOT.parent / "shared" / "data" / "mocap"
    if not mocap.is_dir():
        pytest.skip("../shared/data/mocap is not beside the checkout")
    wrong = [
        f"{_rel(doc)}: {m.group(1)}"
        for doc in doc_files()
        for m in re.finditer(r"shared/data/mocap/([\w.-]+\.(?:bvh|amc|asf|c3d))", doc.read_text())
        if not (mocap / m.group(1)).is_file()
    ]
    assert not wrong, "\n".join(wrong)
