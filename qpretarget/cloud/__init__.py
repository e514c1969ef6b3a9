# SPDX-License-Identifier: Apache-2.0
"""Retargeting straight from depth point clouds (Wang 2017, HUMROB), with a QP M-step.

A template made of the robot's own link meshes (points and normals attached to its joints,
scaled segment by segment to the person) is fitted to every cloud by EM; each M-step is a QP
(ProxSuite) with the joint limits and the robot's balance (CoM over the support polygon) as
constraints. The fitted joint angles are the robot's command. See ``docs/point_clouds.md``.

.. code-block:: python

    from qpretarget.cloud import CloudConfig, CloudRetargeter, read_cloud_sequence

    seq = read_cloud_sequence("clouds.npz")
    run, frames = CloudRetargeter(CloudConfig.from_yaml("configs/cloud_g1.yaml")).run(seq)
    run.save("run.npz")
"""

from .config import CloudConfig
from .em import CloudRetargeter, FrameResult
from .estep import e_step
from .io import (
    CloudFormatError,
    CloudFrame,
    CloudSequence,
    PinholeIntrinsics,
    depth_to_points,
    prepare_cloud,
    read_cloud_sequence,
)
from .meshes import LinkMeshes, load_link_meshes
from .template import Template

__all__ = [
    "CloudConfig",
    "CloudFormatError",
    "CloudFrame",
    "CloudRetargeter",
    "CloudSequence",
    "FrameResult",
    "LinkMeshes",
    "PinholeIntrinsics",
    "Template",
    "depth_to_points",
    "e_step",
    "load_link_meshes",
    "prepare_cloud",
    "read_cloud_sequence",
]
