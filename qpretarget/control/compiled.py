# SPDX-License-Identifier: Apache-2.0
r"""The compiled hot path of a velocity-level tick (``qpretarget._kernel``, built at install).

Every module keeps its Python class, its configuration and its checks; what a module computes
per tick can also run in the C++ kernel (``src/kernel/kernel.cpp``), in one call with no Python
loop over tasks, bounds or contacts. A module opts in with ``compile_into(tick, ...)``
(:meth:`Task.compile_into <qpretarget.tasks.base.Task.compile_into>`,
:meth:`Constraint.compile_into <qpretarget.constraints.base.Constraint.compile_into>`); when
*every* module of a controller does, :meth:`CompiledTick.build` fills the controller's own
buffers (the stacked task rows, the merged box, the constraint rows) exactly as the Python
modules would, and the augmentation strategy assembles its QP in the kernel too
(:math:`H = J_w^\top J_w + \lambda^2 I`, :math:`g = -J_w^\top r_w`, Dariush 2009 4.3.1). The
level, the fallback and the report stay in Python, so a failed tick is handled exactly as
before. The direct DAQP backend (``solvers/daqp_.py``) calls DAQP's C entry point through the
kernel whenever the kernel is installed, with the Python path's inputs.

Results are those of the Python path to round-off (the same pinocchio algorithms on the same
data; the matrix products' summation order may differ by an ulp), and runs stay bit-identical
from one process to the next (no threads, no alignment-dependent code).

``QPRETARGET_KERNEL=0`` in the environment turns the kernel off (the pure Python path), e.g. to
compare the two.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from ..kernel import kernel, why_not
from ..tasks.base import CostBlock, Task


class CompiledTick:
    """The compiled part of a controller's tick (built by :meth:`compile`).

    Modules with a compiled part run in one kernel call; the others run their Python code into
    the same buffers, so a config mixes both freely (a custom task in Python, the rest compiled).

    Attributes:
        compiled_tasks: names of the tasks the kernel computes.
        python_rows: row constraints without a compiled part (their rows come from Python).
        all_bounds: every box-bound module is compiled (the kernel merges the box).
    """

    def __init__(self, ctrl: Any, tick: Any, e_all: np.ndarray) -> None:
        self.ctrl = ctrl
        self.tick = tick
        #: The kernel module (its free functions: the slack QP, DAQP).
        self.module = kernel()
        self.e_all = e_all
        self.compiled_tasks: set[str] = set()
        self.python_rows: set[str] = set()
        self.all_bounds = False
        self.bound_names: list[str] = []
        self._blocks: list[CostBlock] = []
        self._slices: list[slice] = []
        self._box_index: dict[str, int] = {}
        self._has_box: list[float] = []
        self._python: list[tuple[int, Task]] = []  # tasks without a compiled part (fixed)
        self._ramping: dict[int, Task] = {}  # compiled tasks ramping back after a missing target

    @classmethod
    def compile(cls, ctrl: Any) -> tuple[CompiledTick | None, str]:
        """Compile what ``ctrl``'s modules can run in the kernel.

        Returns:
            ``(compiled, "")``, or ``(None, reason)`` when the kernel is missing or has nothing
            to run (the acceleration level, or no module with a compiled part).
        """
        k = kernel()
        if k is None:
            return None, why_not()
        if ctrl.level != "velocity":
            return None, f"level {ctrl.level!r} (the kernel runs the velocity level)"
        tick = k.Tick(ctrl.robot.model, ctrl.state.data)
        e_all = np.zeros_like(ctrl._v_all)
        tick.set_buffers(
            ctrl._J_all, ctrl._v_all, e_all, ctrl._C, ctrl._l, ctrl._u, ctrl._lb, ctrl._ub
        )
        self = cls(ctrl, tick, e_all)
        row = 0
        for t in ctrl.tasks.values():
            sl = slice(row, row + t.dim)
            self._slices.append(sl)
            self._blocks.append(
                CostBlock(t.name, ctrl._J_all[sl], ctrl._v_all[sl], t.weight, t.level, e_all[sl])
            )
            if t.compile_into(tick, row):
                self.compiled_tasks.add(t.name)
            else:
                self._python.append((len(self._blocks) - 1, t))
            row += t.dim
        boxes = [c for c in ctrl.bound_constraints if c.has_bounds]
        # Box modules with a compiled part compute their box in the kernel; the kernel also
        # merges the box when every box module has one, else Python merges them in order.
        self._box_index = {}
        for c in boxes:
            if c.compile_bounds_into(tick):
                self._box_index[c.name] = len(self._box_index)
        self.all_bounds = bool(boxes) and len(self._box_index) == len(boxes)
        if self.all_bounds:
            self.bound_names = [c.name for c in boxes]
        tick.set_merge(self.all_bounds)
        row = 0
        for con in ctrl.row_constraints:
            # A module with a box and rows (the trust region of a distance damper) shares the
            # tick's distances between them: its rows are compiled only with its box.
            shared = con.has_bounds and con.name not in self._box_index
            if shared or not con.compile_rows_into(tick, row):
                self.python_rows.add(con.name)
            row += con.n_rows
        if (
            not self.compiled_tasks
            and not self.all_bounds
            and len(self.python_rows) == len(ctrl.row_constraints)
        ):
            return None, "no module of this config has a compiled part"
        return self, ""

    def describe(self) -> str:
        """What runs compiled and what runs in Python (one line)."""
        py_tasks = [n for n in self.ctrl.tasks if n not in self.compiled_tasks]
        parts = [f"{len(self.compiled_tasks)}/{len(self.ctrl.tasks)} tasks compiled"]
        if py_tasks:
            parts.append("Python tasks: " + ", ".join(py_tasks))
        parts.append("box compiled" if self.all_bounds else "box merged in Python")
        if self.python_rows:
            parts.append("Python rows: " + ", ".join(sorted(self.python_rows)))
        return "; ".join(parts)

    def build(self, dt: float) -> tuple[list[CostBlock], dict[str, float] | None]:
        """This tick's compiled tasks, box and rows in one kernel call, then the Python ones.

        Returns:
            ``(blocks, gave)``: the cost blocks of every task (YAML order) and, when the kernel
            merged the box, bound module name -> how much its box gave (as
            ``Controller._merge_bounds``); ``None`` when the box is left to Python.
        """
        ctrl = self.ctrl
        st = ctrl.state
        q, v = st.q, st.v
        if not (q.flags.c_contiguous and v.flags.c_contiguous):  # a strided view given by a user
            q, v = np.ascontiguousarray(q, dtype=float), np.ascontiguousarray(v, dtype=float)
        g = self.tick.build(q, v, dt)
        blocks = self._blocks
        # Tasks without a compiled part, and compiled ones whose weight ramps back after a
        # missing target (Task.block scales it), write their rows in Python over the kernel's.
        out = None
        if self._python or self._ramping:
            out = list(blocks)
            for i, t in self._python:
                out[i] = t.block(st, dt)
            for i, t in list(self._ramping.items()):
                out[i] = t.block(st, dt)
                if t.presence >= 1.0:
                    del self._ramping[i]
        gave = None
        if self.all_bounds:
            gave = {n: float(x) for n, x in zip(self.bound_names, g, strict=True) if x == x}
        else:
            self._has_box = g
        return (blocks if out is None else out), gave

    def computes_box(self, con: Any) -> bool:
        """``True`` when the kernel computes the box of ``con``."""
        return con.name in self._box_index

    def box(self, con: Any) -> tuple[np.ndarray, np.ndarray] | None:
        """This tick's box of ``con`` as the kernel computed it (``None``: no box this tick)."""
        i = self._box_index[con.name]
        if self._has_box[i] != 1.0:
            return None
        lo, hi = self.tick.box(i)
        return lo, hi

    def note_missing(self, task: Task) -> None:
        """``task`` got a missing (NaN) target: its rows come from Python until it recovers."""
        if task.name in self.compiled_tasks:
            self._ramping[list(self.ctrl.tasks).index(task.name)] = task

    def refresh_weight(self, task: Task) -> None:
        """``task``'s weight array was replaced (a weight scale): its cost block takes it."""
        i = list(self.ctrl.tasks).index(task.name)
        self._blocks[i] = dataclasses.replace(self._blocks[i], weight=task.weight)

    def reset(self) -> None:
        """A reset restores every task's full weight."""
        self._ramping.clear()

    def hessian(self, sqrt_w: np.ndarray, damping2: float, H: np.ndarray, g: np.ndarray) -> None:
        r"""Augmentation's :math:`H = J_w^\top J_w + \lambda^2 I`, :math:`g = -J_w^\top r_w`.

        Over every stacked task row (Dariush 2009 4.3.1, CRAC eq. 10), ``sqrt_w`` the square
        roots of the tick's weights.
        """
        self.tick.hessian(sqrt_w, damping2, H, g)

    def copy_constraints(
        self, C: np.ndarray, l: np.ndarray, u: np.ndarray, lb: np.ndarray, ub: np.ndarray
    ) -> None:
        """Copy this tick's rows and box into a QP's buffers."""
        self.tick.copy_constraints(C, l, u, lb, ub)


__all__ = ["CompiledTick"]
