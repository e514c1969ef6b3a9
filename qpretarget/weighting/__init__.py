# SPDX-License-Identifier: Apache-2.0
"""Regularization metrics W of the weighted damped least squares: identity, WLN and CRAC."""

from . import crac, wln  # noqa: F401  (register wln and crac)
from .base import REGULARIZATIONS, IdentityRegularization, Regularization

__all__ = ["REGULARIZATIONS", "Regularization", "IdentityRegularization"]
