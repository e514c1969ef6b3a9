# SPDX-License-Identifier: Apache-2.0
"""YAML loading for configuration files: PyYAML's safe loader with YAML 1.2 numbers.

PyYAML follows YAML 1.1, where ``1e4`` and ``1.0e4`` (no sign in the exponent) are *strings*;
a config writing ``weight: 1e4`` would then be refused as "not a number". :func:`load_yaml`
reads them as floats, as YAML 1.2 and every other YAML tool do.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

import yaml


class ConfigLoader(yaml.SafeLoader):
    """Safe loader whose floats include ``1e4``, ``1.5E-3``, ``.5``, ``+inf`` and ``.nan``."""


ConfigLoader.yaml_implicit_resolvers = {
    k: [(tag, rx) for tag, rx in v if tag != "tag:yaml.org,2002:float"]
    for k, v in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
ConfigLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(
        r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
        |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
        |[-+]?\.[0-9_]+(?:[eE][-+]?[0-9]+)?
        |[-+]?\.(?:inf|Inf|INF)
        |\.(?:nan|NaN|NAN))$""",
        re.X,
    ),
    list("-+0123456789."),
)


def load_yaml(stream: str | bytes | IO[str]) -> Any:
    """Parse YAML text (or an open file) with :class:`ConfigLoader`."""
    return yaml.load(stream, Loader=ConfigLoader)  # noqa: S506 - a SafeLoader subclass


def read_yaml_file(path: Path, error: Callable[[str], Exception], what: str) -> tuple[str, Any]:
    """The text of the YAML file ``path`` and its content (:func:`load_yaml`).

    Args:
        path: the file.
        error: the error type to raise, called with the message.
        what: what the file is, for the message of a missing file (``"config file"``).

    Raises:
        error: the file is missing, cannot be read, is not UTF-8 text, or is not valid YAML
            (syntax errors name the line and column).
    """
    if not path.is_file():
        raise error(f"{what} {str(path)!r} does not exist.")
    try:
        text = path.read_text(encoding="utf-8")
        return text, load_yaml(text)
    except yaml.MarkedYAMLError as exc:  # syntax errors: where and what
        mark = exc.problem_mark
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        raise error(f"{path}: invalid YAML{where}: {exc.problem or exc}") from None
    except yaml.YAMLError as exc:
        raise error(f"{path}: invalid YAML: {exc}") from None
    except UnicodeDecodeError as exc:
        raise error(f"{path}: not a UTF-8 text file ({exc.reason} at byte {exc.start}).") from None
    except (IsADirectoryError, PermissionError) as exc:
        raise error(f"{path}: cannot be read ({exc.strerror}).") from None


__all__ = ["ConfigLoader", "load_yaml", "read_yaml_file"]
