# SPDX-License-Identifier: Apache-2.0
"""Bundled key-point maps (YAML data, no code); a package so that ``*.yaml`` package data ships."""
