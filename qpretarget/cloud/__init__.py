# SPDX-License-Identifier: Apache-2.0
"""Retargeting from depth point clouds (Wang 2017, HUMROB)."""
