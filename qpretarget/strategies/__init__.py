# SPDX-License-Identifier: Apache-2.0
"""Task-management strategies, registered under their YAML ``type:`` in :data:`STRATEGIES`."""

from .. import weighting  # noqa: F401  (registers the wln and crac metrics)
from . import hierarchy, nullspace, redirection  # noqa: F401  (registers the schemes)
from .augmentation import Augmentation
from .base import STRATEGIES, Strategy, StrategyResult, TickProblem

__all__ = ["STRATEGIES", "Strategy", "StrategyResult", "TickProblem", "Augmentation"]
