"""Validation of the JSON files the FreeCAD import reads (standard library only).

This module runs both in synthdet's Python (the ``freecad`` CLI checks its inputs before
starting FreeCAD) and inside FreeCAD's own Python (the macro checks them again, because it can
be run on its own). Every error names the file and the JSON path of the bad value, e.g.
``pred.json: detections[2].score: expected a finite number, got NaN``.
"""
import json
import math

PREDICTIONS_FORMAT = 'synthdet.predictions/1'
CORNERS_FORMAT = 'synthdet.corners/1'
JOB_FORMAT = 'synthdet.freecad-job/1'
RESULT_FORMAT = 'synthdet.freecad-result/1'

MAX_NAME_LENGTH = 200
MAX_DETECTIONS = 100000
MAX_CORNERS = 10000
MM = 1000.0  # FreeCAD lengths are millimetres
DEGREES = 180.0 / math.pi  # and its angles degrees


class SchemaError(ValueError):
    """A JSON input that does not follow its ``synthdet.*`` contract."""


def load_json(path: str) -> object:
    """Parse a JSON file; syntax errors name the file, line and column."""
    try:
        with open(path, encoding='utf-8') as stream:
            text = stream.read()
    except OSError as error:
        raise SchemaError(f'{path}: cannot read: {error.strerror or error}') from None
    except UnicodeDecodeError as error:
        raise SchemaError(f'{path}: not UTF-8 text ({error.reason})') from None
    if not text.strip():
        raise SchemaError(f'{path}: the file is empty')
    try:
        return json.loads(text)
    except json.JSONDecodeError as error:
        raise SchemaError(
            f'{path}:{error.lineno}:{error.colno}: invalid JSON: {error.msg}') from None


def _fail(source: str, where: str, message: str) -> None:
    raise SchemaError(f'{source}: {where}: {message}' if where else f'{source}: {message}')


def _describe(value: object) -> str:
    if isinstance(value, float) and not math.isfinite(value):
        return str(value).replace('nan', 'NaN').replace('inf', 'Infinity')
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + '...'


def _object(value: object, source: str, where: str, required: tuple[str, ...]) -> dict:
    if not isinstance(value, dict):
        _fail(source, where, f'expected a JSON object, got {type(value).__name__}')
    for key in required:
        if key not in value:
            _fail(source, where, f'missing key "{key}"')
    return value


def _number(value: object, source: str, where: str, unit: float = 1.0) -> float:
    """A finite number that stays finite in FreeCAD's units (``value * unit``: mm, degrees)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        _fail(source, where, f'expected a number, got {_describe(value)}')
    if not math.isfinite(value):
        _fail(source, where, f'expected a finite number, got {_describe(value)}')
    if not math.isfinite(float(value) * unit):
        _fail(source, where, f'{_describe(value)} is not finite once converted to FreeCAD\'s '
              f'units (x {unit:g})')
    return float(value)


def _vector(value: object, length: int, source: str, where: str,
            unit: float = 1.0) -> list[float]:
    if not isinstance(value, list) or len(value) != length:
        _fail(source, where, f'expected a list of {length} numbers, got {_describe(value)}')
    return [_number(item, source, f'{where}[{index}]', unit) for index, item in enumerate(value)]


def _name(value: object, source: str, where: str) -> str:
    if not isinstance(value, str):
        _fail(source, where, f'expected a string, got {_describe(value)}')
    if not value.strip():
        _fail(source, where, 'expected a non-empty name')
    if len(value) > MAX_NAME_LENGTH:
        _fail(source, where, f'name longer than {MAX_NAME_LENGTH} characters ({len(value)})')
    if '\x00' in value:
        _fail(source, where, 'name contains a NUL character')
    return value


def _text(value: object, source: str, where: str) -> str:
    if not isinstance(value, str):
        _fail(source, where, f'expected a string, got {_describe(value)}')
    if '\x00' in value:
        _fail(source, where, 'text contains a NUL character')
    return value


def _format(data: dict, expected: str, source: str) -> None:
    found = data.get('format')
    if found != expected:
        _fail(source, 'format', f'unsupported format {_describe(found)}; this reader knows '
              f'"{expected}"')


def validate_predictions(data: object, source: str = '<predictions>') -> dict:
    """Check a ``synthdet.predictions/1`` document; returns a normalised copy."""
    data = _object(data, source, '', ('format', 'detections'))
    _format(data, PREDICTIONS_FORMAT, source)
    scan = _text(data.get('scan', ''), source, 'scan')
    model = _text(data.get('model', ''), source, 'model')
    classes = data.get('classes', [])
    if not isinstance(classes, list):
        _fail(source, 'classes', f'expected a list of names, got {_describe(classes)}')
    classes = [_name(name, source, f'classes[{index}]') for index, name in enumerate(classes)]
    detections = data['detections']
    if not isinstance(detections, list):
        _fail(source, 'detections', f'expected a list, got {_describe(detections)}')
    if len(detections) > MAX_DETECTIONS:
        _fail(source, 'detections', f'more than {MAX_DETECTIONS} detections')
    checked = []
    for index, detection in enumerate(detections):
        where = f'detections[{index}]'
        detection = _object(detection, source, where, ('class', 'score', 'center', 'size'))
        score = _number(detection['score'], source, f'{where}.score')
        if not 0.0 <= score <= 1.0:
            _fail(source, f'{where}.score', f'expected a score in [0, 1], got {score}')
        size = _vector(detection['size'], 3, source, f'{where}.size', MM)
        if min(size) <= 0.0:
            _fail(source, f'{where}.size', f'expected positive sizes, got {size}')
        checked.append({
            'class': _name(detection['class'], source, f'{where}.class'),
            'score': score,
            'center': _vector(detection['center'], 3, source, f'{where}.center', MM),
            'size': size,
            'yaw': _number(detection.get('yaw', 0.0), source, f'{where}.yaw', DEGREES),
        })
    return {
        'format': PREDICTIONS_FORMAT,
        'scan': scan,
        'model': model,
        'classes': classes,
        'detections': checked
    }


def _signed_area(points: list[list[float]]) -> float:
    total = 0.0
    for index, (x0, y0) in enumerate(points):
        x1, y1 = points[(index + 1) % len(points)]
        total += x0 * y1 - x1 * y0
    return total / 2.0


def _segments_cross(p: list[float], q: list[float], r: list[float], s: list[float]) -> bool:
    """Whether the closed segments pq and rs intersect."""

    def orientation(a, b, c):
        value = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
        return (value > 1e-12) - (value < -1e-12)

    def on_segment(a, b, c):
        return (min(a[0], b[0]) - 1e-12 <= c[0] <= max(a[0], b[0]) + 1e-12
                and min(a[1], b[1]) - 1e-12 <= c[1] <= max(a[1], b[1]) + 1e-12)

    o1, o2, o3, o4 = orientation(p, q, r), orientation(p, q,
                                                       s), orientation(r, s,
                                                                       p), orientation(r, s, q)
    if o1 != o2 and o3 != o4:
        return True
    return ((o1 == 0 and on_segment(p, q, r)) or (o2 == 0 and on_segment(p, q, s))
            or (o3 == 0 and on_segment(r, s, p)) or (o4 == 0 and on_segment(r, s, q)))


def validate_corners(data: object, source: str = '<corners>') -> dict:
    """Check a ``synthdet.corners/1`` document: a simple clockwise polygon and z levels."""
    data = _object(data, source, '', ('format', 'corners', 'floor_z', 'ceiling_z'))
    _format(data, CORNERS_FORMAT, source)
    corners = data['corners']
    if not isinstance(corners, list) or not 3 <= len(corners) <= MAX_CORNERS:
        _fail(source, 'corners', f'expected a list of 3 to {MAX_CORNERS} [x, y] points, got '
              f'{_describe(corners)}')
    points = [
        _vector(point, 2, source, f'corners[{index}]', MM) for index, point in enumerate(corners)
    ]
    count = len(points)
    for index in range(count):
        a, b = points[index], points[(index + 1) % count]
        if math.hypot(b[0] - a[0], b[1] - a[1]) < 1e-6:
            _fail(source, f'corners[{index}]', 'repeats the next corner')
    for i in range(count):
        for j in range(i + 2, count):
            if i == 0 and j == count - 1:
                continue
            if _segments_cross(points[i], points[(i + 1) % count], points[j],
                               points[(j + 1) % count]):
                _fail(source, 'corners', f'the polygon crosses itself (edges {i} and {j})')
    area = _signed_area(points)
    if abs(area) < 1e-9:
        _fail(source, 'corners', 'the polygon has no area')
    if area > 0:
        _fail(source, 'corners', 'the corners run counter-clockwise; the contract is clockwise '
              'seen from above')
    floor_z = _number(data['floor_z'], source, 'floor_z', MM)
    ceiling_z = _number(data['ceiling_z'], source, 'ceiling_z', MM)
    if ceiling_z <= floor_z:
        _fail(source, 'ceiling_z', f'ceiling_z {ceiling_z} is not above floor_z {floor_z}')
    return {
        'format': CORNERS_FORMAT,
        'scan': _text(data.get('scan', ''), source, 'scan'),
        'corners': points,
        'floor_z': floor_z,
        'ceiling_z': ceiling_z
    }


def validate_job(data: object, source: str = '<job>') -> dict:
    """Check a ``synthdet.freecad-job/1`` document, the options of one headless import."""
    data = _object(data, source, '', ('format', 'predictions', 'out'))
    _format(data, JOB_FORMAT, source)
    job = {'format': JOB_FORMAT}
    for key in ('predictions', 'out'):
        job[key] = _text(data[key], source, key)
        if not job[key]:
            _fail(source, key, 'expected a path')
    for key in ('corners', 'library'):
        value = data.get(key)
        job[key] = None if value is None else _text(value, source, key)
    job['min_score'] = _number(data.get('min_score', 0.3), source, 'min_score')
    if not 0.0 <= job['min_score'] <= 1.0:
        _fail(source, 'min_score', f'expected a score in [0, 1], got {job["min_score"]}')
    job['wall_thickness'] = _number(
        data.get('wall_thickness', 0.1), source, 'wall_thickness', MM)
    if job['wall_thickness'] <= 0.0:
        _fail(source, 'wall_thickness', f'expected a positive thickness in metres, got '
              f'{job["wall_thickness"]}')
    return job


def read_predictions(path: str) -> dict:
    """Load and validate a predictions JSON file."""
    return validate_predictions(load_json(path), path)


def read_corners(path: str) -> dict:
    """Load and validate a corners JSON file."""
    return validate_corners(load_json(path), path)


def read_job(path: str) -> dict:
    """Load and validate a FreeCAD job JSON file."""
    return validate_job(load_json(path), path)
