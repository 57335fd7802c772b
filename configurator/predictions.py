"""Reading and checking ``synthdet.predictions/1`` and ``synthdet.corners/1`` files.

The checks live in ``configurator/freecad/synthdet_freecad/schema.py`` (standard library only)
so that the FreeCAD macro, which runs without synthdet, applies exactly the same rules.
"""
from configurator.freecad.synthdet_freecad.schema import (CORNERS_FORMAT, JOB_FORMAT,
                                                          PREDICTIONS_FORMAT, RESULT_FORMAT,
                                                          SchemaError, load_json, read_corners,
                                                          read_predictions, validate_corners,
                                                          validate_job, validate_predictions)

__all__ = [
    'CORNERS_FORMAT', 'JOB_FORMAT', 'PREDICTIONS_FORMAT', 'RESULT_FORMAT', 'SchemaError',
    'load_json', 'read_corners', 'read_predictions', 'validate_corners', 'validate_job',
    'validate_predictions'
]
