"""The generator's asset library: procedural, parametric bpy models of the five object classes
(table, chair, sofa, yumi, 3dprinter), saved as / loaded from one `<class>.blend` per class.

The library's names load on first use, so ``generator.assets.palette`` imports without bpy (the
clutter of ``generator/clutter.py`` uses it in pure numpy)."""
import importlib
from typing import Any

__all__ = [
    'ASSET_CLASSES', 'AssetInstance', 'AssetLibrary', 'build_library', 'default_library',
    'load_library'
]


def __getattr__(name: str) -> Any:
    if name in __all__:
        return getattr(importlib.import_module('generator.assets.library'), name)
    raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
