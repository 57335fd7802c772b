"""The generator's asset library: procedural, parametric bpy models of the five object classes
(table, chair, sofa, yumi, 3dprinter), saved as / loaded from one `<class>.blend` per class."""
from generator.assets.library import (ASSET_CLASSES, AssetInstance, AssetLibrary, build_library,
                                      default_library, load_library)

__all__ = [
    'ASSET_CLASSES', 'AssetInstance', 'AssetLibrary', 'build_library', 'default_library',
    'load_library'
]
