# SPDX-License-Identifier: Apache-2.0
"""Cost modules (tasks). Each registers itself under its YAML ``type:`` name in :data:`TASKS`."""

from .base import TASKS, CostBlock, Task
from .chain_shape import ChainShapeTask  # noqa: F401
from .com import ComTask
from .frame import FrameTask
from .posture import DampingTask, PostureTask

__all__ = ["TASKS", "CostBlock", "Task", "ComTask", "FrameTask", "PostureTask", "DampingTask"]
