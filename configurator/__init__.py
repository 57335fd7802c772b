"""synthdet configurator: room corners from a scan, and detections to a parametric FreeCAD document."""
