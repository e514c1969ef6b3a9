# SPDX-License-Identifier: Apache-2.0
"""The controller YAML's schema: every section's keys, types and defaults, checked in one place.

A controller config is a mapping with the top-level keys :data:`TOP_LEVEL_KEYS`:

================== ====================================================== =====================
key                value                                                  default
================== ====================================================== =====================
``name``           free text                                              none
``description``    free text                                              none
``robot``          bundled name (``g1``) or ``{urdf, srdf, ...}``          required
``dt``             tick length [s] in (0, 1)                              ``0.01``
``level``          ``velocity`` or ``acceleration``                       ``velocity``
``strategy``       registered strategy: name or ``{type, <its keys>}``    ``augmentation``
``regularization`` registered metric: name or ``{type, <its keys>}``      ``identity``
``solver``         registered solver: name or ``{name, <its options>}``   ``daqp``
``tasks``          list of ``{type, <its keys>}`` (at least one)          required
``constraints``    list of ``{type, <its keys>}``                         ``[]``
``fallback``       ``{enabled, ratio, report_tolerance, solver}``         enabled
``acceleration``   ``{kp, kv, gv, velocity_gain}`` (``level: acceleration``) CRAC section 5
``retarget``       the retargeter's section (checked by ``qpretarget.retarget``) none
================== ====================================================== =====================

The keys of a registered type are its constructor's keyword arguments
(:func:`qpretarget.registry.check_keywords` checks them; :func:`options` lists them), so the
schema and the code cannot disagree. Unknown keys fail with the close names.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from .constraints import CONSTRAINTS
from .errors import ConfigError, close_matches_hint
from .registry import Registry, keyword_parameters
from .robot import ERD_PREFIX
from .solvers import SOLVERS, QPSolver
from .strategies import STRATEGIES
from .tasks import TASKS
from .weighting.base import REGULARIZATIONS

#: Every key a controller YAML may have at its top level.
TOP_LEVEL_KEYS = (
    "name", "description", "robot", "dt", "level", "strategy", "regularization", "solver",
    "tasks", "constraints", "fallback", "retarget", "acceleration",
)  # fmt: skip

#: Values of ``level:``.
LEVELS = ("velocity", "acceleration")

#: Default ``dt`` [s].
DEFAULT_DT = 0.01

#: Keys that are not controller settings, with where they go instead.
NOT_CONTROLLER_KEYS = {
    "viewer": "viewer options are flags of the `qpretarget view` command "
    "(see `qpretarget view --help`), not controller settings",
}


def check_top_level(cfg: Mapping[str, Any]) -> None:
    """Check the top-level keys of a controller config.

    Raises:
        ConfigError: on an unknown key (with close names) or a missing ``robot:``.
    """
    for key in cfg:
        if key in NOT_CONTROLLER_KEYS:
            raise ConfigError(
                f"`{key}:` is not a controller setting: {NOT_CONTROLLER_KEYS[key]}. Remove it.",
                path=str(key),
            )
        if key not in TOP_LEVEL_KEYS:
            raise ConfigError(
                f"unknown key {key!r}.{close_matches_hint(str(key), TOP_LEVEL_KEYS)} "
                f"Top-level keys: {', '.join(TOP_LEVEL_KEYS)}.",
                path=str(key),
            )
    if "robot" not in cfg:
        raise ConfigError(
            "missing `robot:` (a bundled name such as g1, or {urdf: PATH}).", path="robot"
        )


def robot_spec(cfg: Mapping[str, Any], base_dir: Path) -> Any:
    """The ``robot:`` entry with relative ``urdf``/``srdf`` paths resolved against ``base_dir``."""
    spec = cfg["robot"]
    if isinstance(spec, Mapping):
        spec = dict(spec)
        for k in ("urdf", "srdf"):
            value = spec.get(k)
            if value is not None and not str(value).startswith(ERD_PREFIX):
                spec[k] = str((base_dir / str(value)).resolve())
    return spec


def tick_length(cfg: Mapping[str, Any]) -> float:
    """``dt:`` [s], a number in (0, 1) (default :data:`DEFAULT_DT`)."""
    dt = cfg.get("dt", DEFAULT_DT)
    if isinstance(dt, bool) or not isinstance(dt, (int, float)) or not 0 < dt < 1:
        raise ConfigError(f"dt must be a number of seconds in (0, 1), got {dt!r}.", path="dt")
    return float(dt)


def control_level(cfg: Mapping[str, Any]) -> str:
    """``level:``, one of :data:`LEVELS` (an ``acceleration:`` section needs ``acceleration``)."""
    level = cfg.get("level", "velocity")
    if level not in LEVELS:
        raise ConfigError(
            f"level must be 'velocity' or 'acceleration', got {level!r}.", path="level"
        )
    if level != "acceleration" and cfg.get("acceleration") is not None:
        raise ConfigError(
            "an `acceleration:` section needs `level: acceleration`.", path="acceleration"
        )
    return str(level)


def typed_section(
    spec: Any, path: str, default_type: str | None = None
) -> tuple[str, dict[str, Any]]:
    """Split a ``{type: NAME, <keys>}`` entry (or a bare ``NAME``) into ``(NAME, keys)``.

    Raises:
        ConfigError: not a mapping or a name, or no ``type:`` and no default.
    """
    if spec is None:
        spec = {}
    if isinstance(spec, str):
        spec = {"type": spec}
    if not isinstance(spec, Mapping):
        raise ConfigError(f"expected a mapping with a `type:` key, got {spec!r}.", path=path)
    spec = dict(spec)
    type_name = spec.pop("type", default_type)
    if type_name is None:
        raise ConfigError("missing `type:`.", path=path)
    return type_name, spec


def typed_list(cfg: Mapping[str, Any], key: str) -> list[tuple[str, str, dict[str, Any]]]:
    """The ``tasks:`` or ``constraints:`` list as ``(yaml path, type name, keys)`` entries.

    Raises:
        ConfigError: the section is not a list.
    """
    spec = cfg.get(key) or []
    if not isinstance(spec, Sequence) or isinstance(spec, str):
        raise ConfigError(f"{key} must be a list of mappings with a `type:`.", path=key)
    out = []
    for i, entry in enumerate(spec):
        path = f"{key}[{i}]"
        type_name, kwargs = typed_section(entry, path)
        out.append((path, type_name, kwargs))
    return out


def constructor_keys(cls: type) -> list[str]:
    """The YAML keys ``cls`` accepts: its constructor's keyword arguments, in signature order."""
    return list(keyword_parameters(cls))


def _registry_options(registry: Registry) -> dict[str, list[str]]:
    return {name: constructor_keys(registry[name]) for name in sorted(registry)}


def _solver_class(name: str) -> type[QPSolver]:
    cls: type[QPSolver] = SOLVERS[name]
    return cls


def options() -> dict[str, dict[str, list[str]]]:
    """Section -> registered type name -> the YAML keys it accepts.

    Sections: ``tasks``, ``constraints``, ``strategy``, ``regularization``, ``solver``. The keys
    come from the constructor signatures, the same source
    :func:`~qpretarget.registry.check_keywords` validates against (``type``/``name`` selecting
    the entry are not listed). The solvers handed to qpsolvers take any option that solver
    knows, unchecked: they are not listed (``solvers.installed_qpsolvers`` lists them).
    """
    return {
        "tasks": _registry_options(TASKS),
        "constraints": _registry_options(CONSTRAINTS),
        "strategy": _registry_options(STRATEGIES),
        "regularization": _registry_options(REGULARIZATIONS),
        "solver": {
            name: _solver_class(name).option_keys()
            for name in sorted(SOLVERS)
            if not _solver_class(name).passes_options
        },
    }


__all__ = [
    "DEFAULT_DT",
    "LEVELS",
    "TOP_LEVEL_KEYS",
    "check_top_level",
    "constructor_keys",
    "control_level",
    "options",
    "robot_spec",
    "tick_length",
    "typed_list",
    "typed_section",
]
