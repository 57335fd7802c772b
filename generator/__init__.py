"""synthdet generator: Blender factory rooms, a fast simulated LiDAR and S3DIS-format output."""
