# SPDX-License-Identifier: Apache-2.0
"""Name -> class registries filled by decorators, and keyword validation against signatures.

Tasks, constraints, strategies, regularization metrics and solvers register themselves under the
``type:`` name used in YAML. :func:`build_from_spec` checks a YAML mapping against the class
constructor's keyword arguments before calling it, so an unknown key or a missing one produces one
clear message with the YAML path, never a ``TypeError`` from deep inside.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping
from typing import Any, TypeVar

from .errors import ConfigError, UnknownNameError, close_matches_hint

T = TypeVar("T")

#: Class -> the name it is registered under (for messages about its YAML keys).
_REGISTERED_NAMES: dict[type, str] = {}


def _yaml_name(cls: type) -> str:
    """The ``type:`` name of a registered class, else its class name."""
    return _REGISTERED_NAMES.get(cls, cls.__name__)


class Registry(dict[str, type]):
    """A named registry of classes."""

    def __init__(self, kind: str) -> None:
        super().__init__()
        self.kind = kind

    def register(self, name: str) -> Callable[[type[T]], type[T]]:
        """Class decorator registering ``cls`` under ``name``."""

        def deco(cls: type[T]) -> type[T]:
            self.add(name, cls)
            cls.type_name = name  # type: ignore[attr-defined]
            _REGISTERED_NAMES[cls] = name
            return cls

        return deco

    def add(self, name: str, cls: type) -> None:
        """Register ``cls`` under ``name`` without naming the class after it.

        For one class serving several names (the qpsolvers adapter registers every solver
        qpsolvers knows).

        Raises:
            ValueError: ``name`` is already registered to another class.
        """
        if name in self and self[name] is not cls:
            raise ValueError(f"{self.kind} {name!r} is registered twice")
        self[name] = cls

    def lookup(self, name: Any, *, path: str) -> type:
        """Return the class registered as ``name`` or raise with close matches."""
        if not isinstance(name, str):
            raise ConfigError(f"{self.kind} type must be a string, got {name!r}.", path=path)
        try:
            return self[name]
        except KeyError:
            raise UnknownNameError(
                f"{self.kind} type",
                name,
                sorted(self),
                path=path,
                fix=f"Known {self.kind} types: {', '.join(sorted(self))}.",
            ) from None


def keyword_parameters(cls: type) -> dict[str, inspect.Parameter]:
    """The YAML keys of ``cls``: its constructor's named parameters, in signature order."""
    sig = inspect.signature(cls)
    return {
        n: p
        for n, p in sig.parameters.items()
        if n != "self" and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
    }


def check_keywords(
    cls: type, spec: Mapping[str, Any], *, path: str, extra: tuple[str, ...] = ()
) -> None:
    """Check that ``spec``'s keys are keyword arguments of ``cls`` and required ones are present."""
    sig = inspect.signature(cls)
    params = keyword_parameters(cls)
    accepts_any = any(p.kind == p.VAR_KEYWORD for p in sig.parameters.values())
    allowed = set(params) | set(extra)
    for key in spec:
        if key not in allowed and not accepts_any:
            raise ConfigError(
                f"unknown key {key!r} for {_yaml_name(cls)!r}."
                f"{close_matches_hint(key, sorted(allowed))} Allowed keys: "
                f"{', '.join(sorted(allowed))}.",
                path=f"{path}.{key}",
            )
    for n, p in params.items():
        if p.default is inspect.Parameter.empty and n not in spec:
            raise ConfigError(
                f"missing required key {n!r} for {_yaml_name(cls)!r}.",
                path=path,
            )


def build_from_spec(cls: type[T], spec: Mapping[str, Any], *, path: str) -> T:
    """Instantiate ``cls(**spec)`` after checking keys; constructor errors get the YAML path."""
    check_keywords(cls, spec, path=path)
    try:
        return cls(**spec)
    except ConfigError as exc:
        if exc.path:
            raise
        raise ConfigError(exc.bare_message, path=path) from None
    except (TypeError, ValueError) as exc:
        raise ConfigError(str(exc), path=path) from None
