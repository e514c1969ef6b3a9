# SPDX-License-Identifier: Apache-2.0
"""Behaviour is unchanged by refactoring: fixed runs reproduce the recorded configurations.

``tests/golden/golden.npz`` was recorded by ``python tests/golden/cases.py --write`` before the
round-2 architecture refactor (commit "golden runs"). Every case re-runs here and must give the
same q to 1e-12 (the runs use daqp, which is bit-reproducible; 1e-12 leaves room for nothing but
a reordering of floating-point sums, which a pure refactor should not even cause). A deliberate
change of behaviour re-records the file and says why in its commit.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).resolve().parent
_spec = importlib.util.spec_from_file_location("golden_cases", HERE / "golden" / "cases.py")
cases = importlib.util.module_from_spec(_spec)
assert _spec.loader is not None
_spec.loader.exec_module(cases)

pytest.importorskip("daqp", reason="the golden runs use daqp (installed by the test extra)")


@pytest.fixture(scope="module")
def golden() -> dict[str, np.ndarray]:
    with np.load(cases.GOLDEN) as z:
        return {k: z[k] for k in z.files}


def test_every_case_is_recorded(golden):
    assert set(golden) == set(cases.CASES)


@pytest.mark.parametrize("name", sorted(cases.CASES))
def test_golden_run_is_reproduced(name, golden):
    q = cases.run_case(name)
    ref = golden[name]
    assert q.shape == ref.shape
    err = float(np.abs(q - ref).max())
    assert err <= 1e-12, f"{name}: q differs from the recorded run by {err:.3e}"
