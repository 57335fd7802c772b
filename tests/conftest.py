"""Session-wide test set-up.

bpy and open3d both ship a ``libtbb`` in different versions and the first one loaded wins;
importing bpy first (as the stack notes require) keeps every later test module safe.
"""
import bpy  # noqa: F401
