"""synthdet's light core: the file contracts, class lists, 2D geometry, scan I/O and drawing.

Every stage (generator, tools, the mmdet3d plugin, the configurator) may import it; it imports
no stage and none of torch, mmcv, mmdet3d, MinkowskiEngine, bpy or open3d. Import the modules
themselves (``synthdet.contracts``, ``synthdet.scan_io``, ...): this package file imports none
of them, so loading one module does not load the others.
"""
