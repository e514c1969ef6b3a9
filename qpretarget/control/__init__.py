# SPDX-License-Identifier: Apache-2.0
"""The control loop: :class:`Controller`, one tick template, velocity and acceleration levels."""

from .controller import Controller, StepResult

__all__ = ["Controller", "StepResult"]
