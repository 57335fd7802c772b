"""The JSON file contracts between the stages: format strings, validators, readers and writers.

- ``synthdet.room/1``: a generated room's ground truth (``meta.json``, written by the generator);
- ``synthdet.predictions/1``: a scan's detections (``<scan>.pred.json``, from tools/predict.py);
- ``synthdet.corners/1``: a scan's room outline (``<scan>.corners.json``, from the corners CLI);
- ``synthdet.labels/1``: a real scan's true boxes (``<scan stem>.labels.json``, written by a
  person), read by the evaluation of labelled scans (``tools/eval_scans.py``).

docs/architecture.md describes the files. Each contract has one validator with one set of rules;
every reader and writer of the project goes through it. Errors are ``SchemaError`` with one line
naming the file and the JSON path of the bad value, e.g.
``pred.json: detections[2].score: expected a finite number, got NaN``.

Standard library only (with ``synthdet.classes``, ``synthdet.geometry`` and
``synthdet.outputs``, which need no more at import): FreeCAD's own Python loads this module
too, to check the files the macro imports.
"""
from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import NoReturn

from synthdet.classes import SEMANTIC_CLASSES
from synthdet.geometry import first_self_crossing, signed_area
from synthdet.outputs import write_text

ROOM_FORMAT = 'synthdet.room/1'
PREDICTIONS_FORMAT = 'synthdet.predictions/1'
CORNERS_FORMAT = 'synthdet.corners/1'
LABELS_FORMAT = 'synthdet.labels/1'
LABELS_SUFFIX = '.labels.json'  # a scan's labels file: <scan stem>.labels.json beside it
# the generator's sensor models, recorded in a room's meta.json as generator.sensor.model
SENSOR_MODELS = ('paper', 'tls', 'tablet', 'depth_frame', 'reconstruction')

MAX_NAME_LENGTH = 200
MAX_DETECTIONS = 100_000
MAX_OBJECTS = 100_000
MAX_CORNERS = 1_000  # a traced hall has tens; FreeCAD builds a wall per corner
MAX_EXTENT = 1000.0  # metres: no box size or room height beyond this
MIN_CORNER_GAP = 1e-6  # metres: closer consecutive corners count as one repeated corner
MM = 1000.0  # FreeCAD's lengths are millimetres ...
DEGREES = 180.0 / math.pi  # ... and its angles degrees: values must stay finite in those units


class SchemaError(ValueError):
    """A JSON file that does not follow its ``synthdet.*`` contract."""


def load_json(path: str | os.PathLike) -> object:
    """Parse a JSON file; errors name the file (and for syntax errors the line and column)."""
    path = os.fspath(path)
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
    except RecursionError:  # no contract nests deeper than a few levels
        raise SchemaError(f'{path}: invalid JSON: arrays or objects nested too deeply') from None
    except ValueError as error:  # Python's limit of digits in an integer (a hint to lift it)
        reason = ('a number with too many digits' if 'digits' in str(error) else
                  str(error).split(';')[0][:80])
        raise SchemaError(f'{path}: invalid JSON: {reason}') from None


def write_json_atomic(path: str | os.PathLike, data: object, indent: int | None = 1) -> None:
    """Write ``data`` as UTF-8 JSON next to ``path`` and rename it into place."""
    write_text_atomic(path,
                       json.dumps(data, indent=indent, ensure_ascii=False, allow_nan=False) + '\n')


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` as UTF-8 through a checked temporary file beside ``path``, renamed into
    place (``synthdet.outputs``); nothing is left behind if encoding or writing fails."""
    write_text(path, text)


# --------------------------------------------------------------------------- value checks


def fail(source: str, where: str, message: str) -> NoReturn:
    """Raise the one-line ``SchemaError`` of a bad value at JSON path ``where``."""
    raise SchemaError(f'{source}: {where}: {message}' if where else f'{source}: {message}')


def _describe(value: object) -> str:
    if isinstance(value, float) and not math.isfinite(value):
        return str(value).replace('nan', 'NaN').replace('inf', 'Infinity')
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + '...'


def expect_object(value: object, source: str, where: str, required: tuple[str, ...]) -> dict:
    """``value`` as a JSON object holding every key of ``required``."""
    if not isinstance(value, dict):
        fail(source, where, f'expected a JSON object, got {type(value).__name__}')
    for key in required:
        if key not in value:
            fail(source, where, f'missing key "{key}"')
    return value


def expect_number(value: object, source: str, where: str, unit: float = 1.0) -> float:
    """``value`` as a finite float (booleans are not numbers) that stays finite times ``unit``
    (the conversion to FreeCAD's millimetres or degrees)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        fail(source, where, f'expected a number, got {_describe(value)}')
    try:
        number = float(value)
    except OverflowError:  # an integer beyond the range of a float
        number = math.inf
    if not math.isfinite(number):
        fail(source, where, f'expected a finite number, got {_describe(value)}')
    if not math.isfinite(number * unit):
        fail(source, where, f'{_describe(value)} is not finite once converted to FreeCAD\'s '
             f'units (x {unit:g})')
    return number


def _extent(value: object, source: str, where: str) -> float:
    """A positive length of at most ``MAX_EXTENT`` metres."""
    number = expect_number(value, source, where)
    if not 0.0 < number <= MAX_EXTENT:
        fail(source, where, f'expected positive sizes up to {MAX_EXTENT:g} m, got {number}')
    return number


def _vector(value: object, length: int, source: str, where: str) -> list[float]:
    """``length`` coordinates in metres (finite in millimetres too)."""
    if not isinstance(value, list) or len(value) != length:
        fail(source, where, f'expected a list of {length} numbers, got {_describe(value)}')
    return [
        expect_number(item, source, f'{where}[{index}]', MM) for index, item in enumerate(value)
    ]


def _size(value: object, source: str, where: str) -> list[float]:
    if not isinstance(value, list) or len(value) != 3:
        fail(source, where, f'expected a list of 3 numbers, got {_describe(value)}')
    return [_extent(item, source, f'{where}[{index}]') for index, item in enumerate(value)]


def expect_text(value: object, source: str, where: str) -> str:
    """``value`` as a string without NUL characters, in valid Unicode: the bytes of a file name
    that are not UTF-8 (lone surrogates in Python) become U+FFFD, so it can be written as
    UTF-8."""
    if not isinstance(value, str):
        fail(source, where, f'expected a string, got {_describe(value)}')
    if '\x00' in value:
        fail(source, where, 'text contains a NUL character')
    try:
        value.encode('utf-8')
    except UnicodeEncodeError:
        errors = 'surrogateescape' if all(
            '\udc80' <= c <= '\udcff' for c in value if '\ud800' <= c <= '\udfff') \
            else 'surrogatepass'
        value = value.encode('utf-8', errors).decode('utf-8', 'replace')
    return value


def _name(value: object, source: str, where: str) -> str:
    value = expect_text(value, source, where)
    if not value.strip():
        fail(source, where, 'expected a non-empty name')
    if len(value) > MAX_NAME_LENGTH:
        fail(source, where, f'name longer than {MAX_NAME_LENGTH} characters ({len(value)})')
    return value


def class_names(value: object, source: str, where: str) -> list[str]:
    """``value`` as a model's class names: a list (or tuple) of distinct non-empty names of at
    most ``MAX_NAME_LENGTH`` characters; a string (``'table'``, not ``['table']``) is refused
    rather than read as one class per letter."""
    if not isinstance(value, (list, tuple)) or not value:
        fail(source, where, f'expected a non-empty list of class names, got {_describe(value)}')
    names = [_name(name, source, f'{where}[{index}]') for index, name in enumerate(value)]
    seen = set()
    for index, name in enumerate(names):
        if name in seen:
            fail(source, f'{where}[{index}]', f'class {name!r} is listed twice')
        seen.add(name)
    return names


def _bounded_list(data: dict, key: str, most: int, source: str) -> list:
    """``data[key]`` as a list of at most ``most`` items (``more than N <key>`` otherwise)."""
    items = data[key]
    if not isinstance(items, list):
        fail(source, key, f'expected a list, got {_describe(items)}')
    if len(items) > most:
        fail(source, key, f'more than {most} {key}')
    return items


def expect_format(data: dict, expected: str, source: str) -> None:
    """Reject any ``format`` but ``expected``, naming the version this reader knows."""
    found = data.get('format')
    if found != expected:
        fail(source, 'format', f'unsupported format {_describe(found)}; this reader knows '
             f'"{expected}"')


def _document(data: object, expected: str, source: str, required: tuple[str, ...]) -> dict:
    """A JSON object of format ``expected`` (checked first: other versions may have other
    keys) holding every key of ``required``."""
    expect_format(expect_object(data, source, '', ()), expected, source)
    return expect_object(data, source, '', required)


def _polygon(value: object, source: str, where: str) -> list[list[float]]:
    """A simple clockwise polygon of 3 to ``MAX_CORNERS`` distinct ``[x, y]`` corners."""
    if not isinstance(value, list) or not 3 <= len(value) <= MAX_CORNERS:
        fail(source, where, f'expected a list of 3 to {MAX_CORNERS} [x, y] points, got '
             f'{_describe(value)}')
    points = [_vector(point, 2, source, f'{where}[{index}]') for index, point in enumerate(value)]
    count = len(points)
    for index in range(count):
        a, b = points[index], points[(index + 1) % count]
        if math.hypot(b[0] - a[0], b[1] - a[1]) < MIN_CORNER_GAP:
            fail(source, f'{where}[{index}]', 'repeats the next corner')
    crossing = first_self_crossing(points)
    if crossing is not None:
        fail(source, where, f'the polygon crosses itself (edges {crossing[0]} and {crossing[1]})')
    area = signed_area(points)
    if abs(area) < 1e-9:
        fail(source, where, 'the polygon has no area')
    if area > 0:
        fail(source, where, 'the corners run counter-clockwise; the contract is clockwise '
             'seen from above')
    return points


def _box(value: dict, source: str, where: str) -> dict:
    return {
        'center': _vector(value['center'], 3, source, f'{where}.center'),
        'size': _size(value['size'], source, f'{where}.size'),
        'yaw': expect_number(value.get('yaw', 0.0), source, f'{where}.yaw', DEGREES),
    }


# --------------------------------------------------------------------------- the contracts


def validate_predictions(data: object, source: str = '<predictions>') -> dict:
    """Check a ``synthdet.predictions/1`` document; returns a normalised copy.

    Detection classes may be any name (a model may know classes this project does not).
    """
    data = _document(data, PREDICTIONS_FORMAT, source, ('detections', ))
    classes = data.get('classes', [])
    if not isinstance(classes, list):
        fail(source, 'classes', f'expected a list of names, got {_describe(classes)}')
    detections = _bounded_list(data, 'detections', MAX_DETECTIONS, source)
    checked = []
    for index, detection in enumerate(detections):
        where = f'detections[{index}]'
        detection = expect_object(detection, source, where, ('class', 'score', 'center', 'size'))
        score = expect_number(detection['score'], source, f'{where}.score')
        if not 0.0 <= score <= 1.0:
            fail(source, f'{where}.score', f'expected a score in [0, 1], got {score}')
        checked.append({
            'class': _name(detection['class'], source, f'{where}.class'),
            'score': score,
            **_box(detection, source, where)
        })
    return {
        'format': PREDICTIONS_FORMAT,
        'scan': expect_text(data.get('scan', ''), source, 'scan'),
        'model': expect_text(data.get('model', ''), source, 'model'),
        'classes': [_name(name, source, f'classes[{i}]') for i, name in enumerate(classes)],
        'detections': checked
    }


def validate_corners(data: object, source: str = '<corners>') -> dict:
    """Check a ``synthdet.corners/1`` document (a simple clockwise polygon, the floor below the
    ceiling, quality figures); returns a normalised copy."""
    data = _document(data, CORNERS_FORMAT, source,
                     ('scan', 'corners', 'floor_z', 'ceiling_z', 'quality'))
    points = _polygon(data['corners'], source, 'corners')
    floor_z = expect_number(data['floor_z'], source, 'floor_z', MM)
    ceiling_z = expect_number(data['ceiling_z'], source, 'ceiling_z', MM)
    if ceiling_z <= floor_z:
        fail(source, 'ceiling_z', f'ceiling_z {ceiling_z} is not above floor_z {floor_z}')
    quality = expect_object(data['quality'], source, 'quality', ())
    return {
        'format': CORNERS_FORMAT,
        'scan': expect_text(data['scan'], source, 'scan'),
        'corners': points,
        'floor_z': floor_z,
        'ceiling_z': ceiling_z,
        'quality': {
            _name(key, source, 'quality'): expect_number(value, source, f'quality.{key}')
            for key, value in quality.items()
        }
    }


def validate_room(data: object, source: str = '<room>') -> dict:
    """Check a ``synthdet.room/1`` document: a simple clockwise floor polygon, a positive
    height, objects of known classes with unique instance names and boxes, ``on`` naming
    another object. Returns the document itself (it may hold more, e.g. the generator's
    settings)."""
    data = _document(data, ROOM_FORMAT, source, ('room', 'objects'))
    room = expect_object(data['room'], source, 'room', ('polygon', 'height'))
    _polygon(room['polygon'], source, 'room.polygon')
    _extent(room['height'], source, 'room.height')
    objects = data['objects']
    if not isinstance(objects, list) or len(objects) > MAX_OBJECTS:
        fail(source, 'objects', f'expected a list of at most {MAX_OBJECTS} objects, got '
             f'{_describe(objects)}')
    instances = set()
    for index, item in enumerate(objects):
        where = f'objects[{index}]'
        item = expect_object(item, source, where, ('instance', 'class', 'box'))
        instance = _name(item['instance'], source, f'{where}.instance')
        if instance in instances:
            fail(source, f'{where}.instance', f'instance {instance!r} appears twice')
        instances.add(instance)
        cls = _name(item['class'], source, f'{where}.class')
        if cls not in SEMANTIC_CLASSES:
            fail(source, f'{where}.class', f'unknown class {_describe(cls)}; known: '
                 f'{", ".join(SEMANTIC_CLASSES)}')
        box = expect_object(item['box'], source, f'{where}.box', ('center', 'size'))
        _box(box, source, f'{where}.box')
    for index, item in enumerate(objects):
        support = item.get('on')
        if support is not None and (support not in instances or support == item['instance']):
            fail(source, f'objects[{index}].on', f'{_describe(support)} is not another object '
                 'of this room')
    return data


def validate_labels(data: object, source: str = '<labels>') -> dict:
    """Check a ``synthdet.labels/1`` document: the scan's name, the distinct labelled
    ``classes`` (at least one) and boxes of those classes; returns a normalised copy.

    Class names may be any name (a model may know classes this project does not); a box of a
    class missing from ``classes`` is refused: ``classes`` says what was labelled. Other keys
    (``source``, ``frame``) are kept as they are.
    """
    data = _document(data, LABELS_FORMAT, source, ('scan', 'classes', 'boxes'))
    names = class_names(data['classes'], source, 'classes')
    boxes = _bounded_list(data, 'boxes', MAX_OBJECTS, source)
    checked = []
    for index, box in enumerate(boxes):
        where = f'boxes[{index}]'
        box = expect_object(box, source, where, ('class', 'center', 'size'))
        cls = _name(box['class'], source, f'{where}.class')
        if cls not in names:
            fail(source, f'{where}.class', f'class {cls!r} is not in "classes" '
                 f'({", ".join(names)})')
        checked.append({'class': cls, **_box(box, source, where)})
    return {
        **data,
        'format': LABELS_FORMAT,
        'scan': _name(data['scan'], source, 'scan'),
        'classes': names,
        'boxes': checked,
    }


def read_predictions(path: str | os.PathLike) -> dict:
    """Load and validate a ``synthdet.predictions/1`` file; returns the normalised document."""
    return validate_predictions(load_json(path), os.fspath(path))


def read_corners(path: str | os.PathLike) -> dict:
    """Load and validate a ``synthdet.corners/1`` file; returns the normalised document."""
    return validate_corners(load_json(path), os.fspath(path))


def read_room(path: str | os.PathLike) -> dict:
    """Load and validate a ``synthdet.room/1`` file (a ``meta.json``); returns the document."""
    return validate_room(load_json(path), os.fspath(path))


def labels_path(scan: str | os.PathLike) -> Path:
    """The labels file of a scan: ``<scan stem>.labels.json`` beside it."""
    scan = Path(scan)
    return scan.with_name(scan.stem + LABELS_SUFFIX)


def read_labels(path: str | os.PathLike) -> dict:
    """Load and validate a ``synthdet.labels/1`` file; returns the normalised document."""
    return validate_labels(load_json(path), os.fspath(path))


def write_predictions(path: str | os.PathLike, document: dict) -> None:
    """Validate a ``synthdet.predictions/1`` document and write it atomically."""
    write_json_atomic(path, validate_predictions(document, os.fspath(path)), indent=2)


def write_corners(path: str | os.PathLike, document: dict) -> None:
    """Validate a ``synthdet.corners/1`` document and write it atomically, one key a line."""
    document = validate_corners(document, os.fspath(path))
    lines = [f'  {json.dumps(key)}: {json.dumps(value)}' for key, value in document.items()]
    write_text_atomic(path, '{\n' + ',\n'.join(lines) + '\n}\n')


def write_room(path: str | os.PathLike, document: dict) -> None:
    """Validate a ``synthdet.room/1`` document and write it atomically."""
    write_json_atomic(path, validate_room(document, os.fspath(path)), indent=1)


def write_labels(path: str | os.PathLike, document: dict) -> None:
    """Validate a ``synthdet.labels/1`` document and write it atomically."""
    write_json_atomic(path, validate_labels(document, os.fspath(path)), indent=1)
