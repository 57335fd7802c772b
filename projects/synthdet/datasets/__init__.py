"""synthdet datasets (registered with mmdet3d on import)."""
