# SPDX-License-Identifier: Apache-2.0
"""Datasets: retarget many clips (a process pool or Ray), resample, export for trainers."""

from .exports import EXPORTS, export_run
from .resample import resample_run

__all__ = ["EXPORTS", "export_run", "resample_run"]
