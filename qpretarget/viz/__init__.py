# SPDX-License-Identifier: Apache-2.0
"""Seeing a motion: robot meshes, an interactive browser viewer (viser) and offscreen rendering.

The viewer needs the optional ``viz`` extra (``pip install qpretarget[viz]``); rendering needs
matplotlib and Pillow (``qpretarget[plot]``). The core package imports neither.
"""
