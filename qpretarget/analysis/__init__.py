# SPDX-License-Identifier: Apache-2.0
"""Measuring runs: metrics (one definition each), plots, solver comparison and benchmarks.

Submodules are imported where used (``from qpretarget.analysis.metrics import ...``) so that
importing one does not load matplotlib or the solvers.
"""
