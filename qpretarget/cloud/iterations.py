# SPDX-License-Identifier: Apache-2.0
r"""What the EM fit (:mod:`.em`) records of its iterations and line searches.

:class:`IterationLog`: one EM iteration of a frame (its stage, the NLL before it, the step length
accepted, the halvings, :math:`\sigma^2` after it), the entries of :attr:`.em.FrameResult.log`.
:class:`_Trial`: the outcome of an M-step's line search (:mod:`.em`, *Monotonicity*).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .template import PosedTemplate


@dataclass
class _Trial:
    """Outcome of an M-step's line search: accepted or not, step length, the point tried."""

    accepted: bool
    alpha: float
    halvings: int
    increase: bool  # the full step increased the objective
    q: np.ndarray
    posed: PosedTemplate


@dataclass
class IterationLog:
    """One EM iteration: NLL before it, the step length accepted, halvings, sigma^2 after."""

    stage: str
    nll: float
    objective: float
    alpha: float
    backtracks: int
    sigma2: float
    max_joint_step: float
    q_full_step_increase: bool = False


__all__ = ["IterationLog"]
