# SPDX-License-Identifier: Apache-2.0
"""Seeing a motion: robot meshes, an interactive browser viewer (viser) and offscreen rendering.

The viewer needs the optional ``viz`` extra; rendering needs matplotlib and Pillow (the ``plot``
extra). The core package imports neither; a missing one raises
:class:`~qpretarget.errors.MissingDependencyError` with the install command
(:func:`~qpretarget.errors.install_hint`).
"""
