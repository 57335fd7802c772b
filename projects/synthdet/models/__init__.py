"""synthdet models (registered with mmdet3d on import)."""
