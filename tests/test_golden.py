# SPDX-License-Identifier: Apache-2.0
"""Behaviour is unchanged by refactoring: fixed runs reproduce the recorded configurations.

``tests/golden/golden.npz`` was recorded by ``python tests/golden/cases.py --write`` before the
round-2 architecture refactor (commit "golden runs"). Every case re-runs here and must give the
same q to 1e-12 (the runs use daqp, which is bit-reproducible; 1e-12 leaves room for nothing but
a reordering of floating-point sums, which a pure refactor should not even cause). A deliberate
change of behaviour re-records the file and says why in its commit.

The cases run in one child process with the floating-point environment pinned
(``cases.pinned_env``: OpenBLAS's generic kernels, numpy's baseline loops), so that the
recording holds on every x86-64 CPU, not only the one it was made on (an AVX-512 Xeon's
recording differed from an AVX2 EPYC's run by 2e-5 rad on the CRAC case).
"""

from __future__ import annotations

import importlib.util
import json
import platform
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


@pytest.fixture(scope="module")
def rerun() -> dict[str, np.ndarray]:
    return cases.run_pinned(sorted(cases.CASES))


def test_every_case_is_recorded(golden):
    assert set(golden) - {cases.PLATFORM_KEY} == set(cases.CASES)


def test_the_recording_says_where_it_was_made(golden):
    meta = json.loads(str(golden[cases.PLATFORM_KEY]))
    assert meta["platform"].split()[0] == platform.machine(), (
        f"golden runs recorded on {meta['platform']!r}, this is {cases.platform_tag()!r}: the "
        "pinned environment makes x86-64 machines agree, not other architectures; re-record "
        "with `python tests/golden/cases.py --write` on this one"
    )


def test_the_pinned_environment_pins_blas_and_numpy():
    env = cases.pinned_env()
    from numpy._core import _multiarray_umath as umath

    assert set(env["NPY_DISABLE_CPU_FEATURES"].split()) == set(umath.__cpu_dispatch__)
    if platform.machine().lower() in ("x86_64", "amd64"):
        assert env["OPENBLAS_CORETYPE"] == "Prescott"


@pytest.mark.parametrize("name", sorted(cases.CASES))
def test_golden_run_is_reproduced(name, golden, rerun):
    q = rerun[name]
    ref = golden[name]
    assert q.shape == ref.shape
    err = float(np.abs(q - ref).max())
    assert err <= 1e-12, f"{name}: q differs from the recorded run by {err:.3e}"
