# SPDX-License-Identifier: Apache-2.0
"""Tests of load_motion: dispatch by extension and ASF discovery."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from qpretarget.motion import find_asf, load_motion, read_asf_amc


def test_dispatch_by_extension(mocap):
    assert load_motion(mocap / "cmu_16_15_walk.bvh").meta["format"] == "bvh"
    assert load_motion(mocap / "opensim_walking2.c3d").meta["format"] == "c3d"
    amc = load_motion(mocap / "cmu_14_37.amc")
    assert amc.meta["format"] == "asf/amc" and amc.meta["asf"].endswith("cmu_14.asf")


@pytest.mark.parametrize(
    ("amc", "asf"), [("cmu_16_15.amc", "cmu_16.asf"), ("cmu_01_01.amc", "cmu_01.asf")]
)
def test_cmu_sibling_asf_is_found(mocap, amc, asf):
    assert find_asf(mocap / amc) == mocap / asf


def test_explicit_asf_and_reader_options_are_passed(mocap, tmp_path):
    shutil.copy(mocap / "cmu_14_37.amc", tmp_path / "trial.amc")
    with pytest.raises(FileNotFoundError, match=r"tried \['trial\.asf'\]; pass asf="):
        load_motion(tmp_path / "trial.amc")
    motion = load_motion(tmp_path / "trial.amc", asf=mocap / "cmu_14.asf", rate=60.0)
    assert motion.rate == 60.0
    reference = read_asf_amc(mocap / "cmu_14.asf", mocap / "cmu_14_37.amc")
    np.testing.assert_array_equal(motion.positions, reference.positions)
    shutil.copy(mocap / "cmu_14.asf", tmp_path / "only.asf")  # the folder's only ASF is used
    assert find_asf(tmp_path / "trial.amc") == tmp_path / "only.asf"


def test_unsupported_files(mocap, tmp_path):
    with pytest.raises(ValueError, match=r"is an ASF skeleton; load the AMC motion instead"):
        load_motion(mocap / "cmu_16.asf")
    with pytest.raises(ValueError, match=r"unsupported extension '\.txt'; supported: \.bvh"):
        load_motion(tmp_path / "motion.txt")
    with pytest.raises(FileNotFoundError, match="does not exist"):
        load_motion(tmp_path / "missing.bvh")
