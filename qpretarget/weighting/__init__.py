# SPDX-License-Identifier: Apache-2.0
"""Regularization metrics W of the weighted damped least squares: identity, WLN and CRAC."""

from . import metrics  # noqa: F401  (registers wln and crac)
from .base import REGULARIZATIONS, IdentityRegularization, Regularization

__all__ = ["REGULARIZATIONS", "Regularization", "IdentityRegularization"]
