"""synthdet mmdet3d plugin: datasets, TR3D model and box ops, registered on import.

Configs load it with ``custom_imports=dict(imports=['projects.synthdet'])``.
"""
from . import core, datasets, models  # noqa: F401
