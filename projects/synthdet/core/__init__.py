"""synthdet core (registered with mmdet3d on import)."""
