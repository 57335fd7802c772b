"""The FreeCAD import's own JSON files, and the project's contracts it reads.

The ``synthdet.predictions/1`` and ``synthdet.corners/1`` rules are the project's, from
``synthdet.contracts`` (standard library only), so that the FreeCAD macro, which may be run on
its own, checks its inputs exactly as the ``freecad`` CLI does. ``ImportSynthdet.FCMacro``
makes the repository (or the site-packages folder synthdet is installed in) importable. This
module adds the job (``synthdet.freecad-job/1``, the options of one headless import) and
result (``synthdet.freecad-result/1``) formats, which only the CLI and the macro exchange.
"""
# SchemaError, read_corners and read_predictions are used by macro.py through this module
from synthdet.contracts import (MM, SchemaError, expect_format, expect_number,  # noqa: F401
                                expect_object, expect_text, fail, load_json, read_corners,
                                read_predictions)

JOB_FORMAT = 'synthdet.freecad-job/1'
RESULT_FORMAT = 'synthdet.freecad-result/1'
# what the macro reports when it reads a document's labels (``labels.run_headless``)
LABELS_READ_FORMAT = 'synthdet.freecad-labels/1'


def validate_job(data: object, source: str = '<job>') -> dict:
    """Check a ``synthdet.freecad-job/1`` document, the options of one headless import."""
    data = expect_object(data, source, '', ('format', 'predictions', 'out'))
    expect_format(data, JOB_FORMAT, source)
    job = {'format': JOB_FORMAT}
    for key in ('predictions', 'out'):
        job[key] = expect_text(data[key], source, key)
        if not job[key]:
            fail(source, key, 'expected a path')
    for key in ('corners', 'library'):
        value = data.get(key)
        job[key] = None if value is None else expect_text(value, source, key)
    job['min_score'] = expect_number(data.get('min_score', 0.3), source, 'min_score')
    if not 0.0 <= job['min_score'] <= 1.0:
        fail(source, 'min_score', f'expected a score in [0, 1], got {job["min_score"]}')
    job['wall_thickness'] = expect_number(
        data.get('wall_thickness', 0.1), source, 'wall_thickness', MM)
    if job['wall_thickness'] <= 0.0:
        fail(source, 'wall_thickness', f'expected a positive thickness in metres, got '
             f'{job["wall_thickness"]}')
    return job


def read_job(path: str) -> dict:
    """Load and validate a FreeCAD job JSON file."""
    return validate_job(load_json(path), path)
