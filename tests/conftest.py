"""Test set-up shared by the whole suite.

- OpenMP threads spin while waiting by default; on the 2 shared cores of a CI machine that makes
  MinkowskiEngine's CPU kernels several times slower. Passive waiting must be set before the
  OpenMP runtime loads, so it comes first (child processes inherit it).
- bpy and open3d both ship a ``libtbb`` in different versions and the first one loaded wins;
  importing bpy first (as the stack notes require) keeps every later test module safe.
"""
import os

os.environ.setdefault('OMP_WAIT_POLICY', 'PASSIVE')

import bpy  # noqa: E402,F401
