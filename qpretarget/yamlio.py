# SPDX-License-Identifier: Apache-2.0
"""YAML loading for configuration files: PyYAML's safe loader with YAML 1.2 numbers.

PyYAML follows YAML 1.1, where ``1e4`` and ``1.0e4`` (no sign in the exponent) are *strings*;
a config writing ``weight: 1e4`` would then be refused as "not a number". :func:`load_yaml`
reads them as floats, as YAML 1.2 and every other YAML tool do.
"""

from __future__ import annotations

import re
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


__all__ = ["ConfigLoader", "load_yaml"]
