"""A corrected synthdet FreeCAD document as training data: its labels and an S3DIS room.

``make_labels`` reads every counted synthdet part of the document inside ``freecadcmd`` (the
``freecad`` sub-command's runner and macro, ``synthdet_freecad.labels``), then, in the scan's
own coordinates:

- writes ``<scan stem>.labels.json`` (``synthdet.labels/1``, what ``tools/eval_scans.py``
  reads beside a scan);
- gives every scan point to one box (``point_owners``): the smallest box it lies in (boxes
  may overlap, as a chair pushed under a table), else the nearest box it lies within
  ``BOX_MARGIN`` of, counting only points above the box's bottom by more than
  ``BOTTOM_CLEARANCE``: the floor under a part and the table top under a part standing on it
  stay outside. A box left without a point of its own (a part duplicated in place) gets an
  annotation file repeating the points in its reach, and a warning (``shadowed_boxes``);
- names the other points by the room's outline, as the generator's structure elements:
  ``floor_1`` within ``SURFACE_BAND`` of the floor, ``ceiling_1`` of the ceiling, ``wall_<i>``
  within ``SURFACE_BAND`` of the wall from corner i to corner i + 1 (1-based, the outline in
  the document's order), the rest ``clutter_1``;
- writes them as ``Area_<N>/<room>/<room>.txt`` and ``Annotations/<class>_<k>.txt``
  (``x y z r g b``, millimetres, colors 0-255) for ``tools/create_data.py``.

A box without a scan point in its reach and a document that is not synthdet's are
``LabelsInputError`` with one line naming the document; a document FreeCAD would run code or
open other files for is refused before FreeCAD starts (``synthdet.fcstd_guard``).
"""
import os
import re
from pathlib import Path

import numpy as np

from configurator.freecad.synthdet_freecad.schema import LABELS_READ_FORMAT as READ_FORMAT
from configurator.freecad_cli import MACRO, FreecadFailed, check_timeout, run_freecad_process
from synthdet.cli import check_input_file
from synthdet.classes import GENERATED_CLASSES
from synthdet.contracts import LABELS_FORMAT, write_labels
from synthdet.fcstd_guard import check_document
from synthdet.outputs import check_output, replaced_paths
from synthdet.processes import work_folder
from synthdet.scan_io import read_scan

BOX_MARGIN = 0.005  # metres a point may lie outside its box (sizes rounded to mm, rounding)
BOTTOM_CLEARANCE = 0.0005  # metres above a box's bottom before a point is the box's
SURFACE_BAND = 0.05  # metres from the floor, ceiling or a wall a point is that surface's
ROOM_NAME = re.compile(r'[A-Za-z0-9]+_[0-9]+')
CLASS_NAME = re.compile(r'[A-Za-z0-9]{1,100}')


class LabelsInputError(ValueError):
    """The document, scan or options cannot be turned into labels (exit code 2)."""


def read_document(document: Path, freecadcmd: str = 'freecadcmd', timeout: float = 300.0) -> dict:
    """The document's counted parts (``boxes``), ``room`` outline and ``reviewed`` flag, read
    by FreeCAD. Raises ``RefusedDocument`` for a file FreeCAD would run code or open other
    files for (``synthdet.fcstd_guard``), ``LabelsInputError`` for one that is not a synthdet
    document."""
    document = Path(document).resolve()
    check_document(document)  # RefusedDocument, a ValueError: exit 2 with one line
    check_timeout(timeout)
    with work_folder('synthdet-labels') as work_dir:
        result_path = work_dir / 'result.json'
        env = dict(os.environ, SYNTHDET_READ=str(document), SYNTHDET_RESULT=str(result_path))
        env.pop('SYNTHDET_JOB', None)
        result = run_freecad_process([freecadcmd, str(MACRO)], env, work_dir, timeout, result_path)
    if not isinstance(result, dict) or result.get('format') != READ_FORMAT:
        raise FreecadFailed(f'{document}: FreeCAD wrote no {READ_FORMAT} result')
    if result.get('status') != 'ok':
        if result.get('kind') == 'input':
            raise LabelsInputError(f'{document}: {result.get("error")}')
        raise FreecadFailed(f'{document}: FreeCAD could not read it: {result.get("error")}')
    return result


def _outside(xyz: np.ndarray, box: dict) -> np.ndarray:
    """How far each point lies outside the box (0 inside; metres, the largest excess along
    the box's axes), infinite for points not above its bottom by ``BOTTOM_CLEARANCE``."""
    (x, y, z), (length, width, height), yaw = box['center'], box['size'], box['yaw']
    cos, sin = np.cos(yaw), np.sin(yaw)
    dx, dy = xyz[:, 0] - x, xyz[:, 1] - y
    along, across = cos * dx + sin * dy, -sin * dx + cos * dy
    bottom, top = z - height / 2.0, z + height / 2.0
    excess = np.maximum.reduce([
        np.abs(along) - length / 2.0,
        np.abs(across) - width / 2.0, xyz[:, 2] - top,
        np.zeros(len(xyz))
    ])
    return np.where(xyz[:, 2] > bottom + BOTTOM_CLEARANCE, excess, np.inf)


def in_reach(xyz: np.ndarray, box: dict, margin: float = BOX_MARGIN) -> np.ndarray:
    """Which points lie in the box or within ``margin`` metres of it (above its bottom)."""
    return _outside(xyz, box) <= margin


def holds_points(xyz: np.ndarray, box: dict) -> bool:
    """Whether a point lies in the box or within ``BOX_MARGIN`` of it (above its bottom)."""
    return bool(in_reach(xyz, box).any())


def box_volume(box: dict) -> float:
    """The box's volume (cubic metres)."""
    return float(np.prod(box['size']))


def point_owners(xyz: np.ndarray, boxes: list[dict], source: str) -> np.ndarray:
    """Index of the box each point belongs to, -1 for none. A point inside boxes belongs to the
    smallest of them (by volume; the first in document order among equal ones); a point inside
    none belongs to the nearest box within ``BOX_MARGIN`` of it. Raises ``LabelsInputError`` for
    a box with no scan point inside it or within ``BOX_MARGIN``."""
    owners = np.full(len(xyz), -1, dtype=np.int64)
    nearest = np.full(len(xyz), np.inf)
    order = sorted(range(len(boxes)), key=lambda index: box_volume(boxes[index]))
    for index in order:  # smallest first: an equal distance (0 inside) keeps the smaller box
        outside = _outside(xyz, boxes[index])
        if not (outside <= BOX_MARGIN).any():
            raise LabelsInputError(f'{source}: {boxes[index]["label"]!r} holds no scan point: '
                                   'move it onto its object or delete it')
        closer = (outside <= BOX_MARGIN) & (outside < nearest)
        owners[closer] = index
        nearest[closer] = outside[closer]
    return owners


def shadowed_boxes(xyz: np.ndarray, boxes: list[dict], owners: np.ndarray,
                   source: str) -> tuple[dict[int, np.ndarray], list[str]]:
    """The boxes left without a point of their own (every point in their reach went to a
    smaller or nearer box, e.g. a part duplicated in place): for each, the indices of the
    points in its reach, which its annotation file repeats, and one warning line each."""
    repeated: dict[int, np.ndarray] = {}
    warnings = []
    for index in np.flatnonzero(np.bincount(owners[owners >= 0], minlength=len(boxes)) == 0):
        reach = np.flatnonzero(_outside(xyz, boxes[index]) <= BOX_MARGIN)
        takers = ', '.join(repr(boxes[owner]['label']) for owner in np.unique(owners[reach]))
        repeated[int(index)] = reach
        warnings.append(f'{source}: every scan point of {boxes[index]["label"]!r} belongs to '
                        f'{takers}: its annotation file repeats those {len(reach)} points')
    return repeated, warnings


def instance_names(boxes: list[dict], source: str) -> list[str]:
    """The S3DIS annotation name of each box, ``<class>_<k>`` numbered per class in order.
    Raises ``LabelsInputError`` for a class that cannot name an annotation file (S3DIS class
    names are letters and digits)."""
    counts: dict[str, int] = {}
    names = []
    for box in boxes:
        if not CLASS_NAME.fullmatch(box['class']):
            raise LabelsInputError(f'{source}: part {box["label"]!r} has class '
                                   f'{box["class"][:40]!r}: an S3DIS class name is letters and '
                                   'digits only (rename its DetectedClass)')
        counts[box['class']] = counts.get(box['class'], 0) + 1
        names.append(f'{box["class"]}_{counts[box["class"]]}')
    return names


def background_elements(xyz: np.ndarray, room: dict | None) -> np.ndarray:
    """The structure element name of each point (``floor_1``, ``ceiling_1``, ``wall_<i>``,
    ``clutter_1``) by the room outline (all ``clutter_1`` without a room)."""
    names = np.full(len(xyz), 'clutter_1', dtype=object)
    if room is None:
        return names
    corners = np.asarray(room['corners'], dtype=np.float64)
    distances = []
    for index in range(len(corners)):
        start, end = corners[index], corners[(index + 1) % len(corners)]
        edge = end - start
        t = np.clip(((xyz[:, :2] - start) @ edge) / max(edge @ edge, 1e-12), 0.0, 1.0)
        distances.append(np.linalg.norm(xyz[:, :2] - (start + t[:, None] * edge), axis=1))
    distances = np.stack(distances, axis=1)
    nearest = np.argmin(distances, axis=1)
    walls = distances[np.arange(len(xyz)), nearest] <= SURFACE_BAND
    names[walls] = np.char.add('wall_', (nearest[walls] + 1).astype(str)).astype(object)
    names[np.abs(xyz[:, 2] - room['ceiling_z']) <= SURFACE_BAND] = 'ceiling_1'
    names[np.abs(xyz[:, 2] - room['floor_z']) <= SURFACE_BAND] = 'floor_1'
    return names


def _write_points(path: Path, points: np.ndarray) -> None:
    rows = np.column_stack([points[:, :3], np.clip(np.rint(points[:, 3:6]), 0, 255)])
    np.savetxt(path, rows, fmt='%.3f %.3f %.3f %d %d %d')


def write_s3dis_room(room_dir: Path,
                     points: np.ndarray,
                     elements: np.ndarray,
                     repeated: dict[str, np.ndarray] | None = None) -> None:
    """Write one S3DIS room (``<room>.txt`` and ``Annotations/<element>.txt``) atomically: in
    a temporary folder of this run beside ``room_dir``, renamed into place (a previous room
    replaced; ``synthdet.outputs``, which also removes the folders of killed runs).
    ``repeated`` maps further annotation names to the indices of points they repeat."""
    with replaced_paths([room_dir], folders=True) as (partial, ):
        annotations = partial / 'Annotations'
        annotations.mkdir()
        order = np.argsort(elements, kind='stable')
        names, starts = np.unique(elements[order], return_index=True)
        for name, chunk in zip(names, np.split(order, starts[1:])):
            _write_points(annotations / f'{name}.txt', points[chunk])
        for name, chunk in (repeated or {}).items():
            _write_points(annotations / f'{name}.txt', points[chunk])
        _write_points(partial / f'{room_dir.name}.txt', points[order])


def labels_document(read: dict, scan: Path) -> dict:
    """The ``synthdet.labels/1`` document of the read boxes; ``classes`` are the generated
    classes and every other class in the document."""
    names = list(GENERATED_CLASSES)
    names += [
        name for name in dict.fromkeys(box['class'] for box in read['boxes']) if name not in names
    ]
    boxes = [{
        key: box[key]
        for key in ('class', 'center', 'size', 'yaw')
    } for box in read['boxes']]
    source = 'synthdet FreeCAD document' + (', reviewed' if read['reviewed'] else '')
    return {
        'format': LABELS_FORMAT,
        'scan': scan.name,
        'classes': names,
        'boxes': boxes,
        'source': source
    }


def make_labels(document: Path,
                scan: Path,
                out: Path,
                area: int = 10,
                room_name: str | None = None,
                freecadcmd: str = 'freecadcmd',
                timeout: float = 300.0) -> dict:
    """Read the document, write the labels file and the S3DIS room into ``out``; returns a
    summary (``labels``, ``room_dir``, ``boxes`` per class, ``points``, ``object_points``,
    ``reviewed``, ``warnings``: one line per box whose annotation repeats other boxes' points)."""
    check_output(out, '--out', inputs=[document, scan], folder=True)
    document, scan, out = Path(document), Path(scan), Path(out)
    room_name = room_name or f'{re.sub(r"[^A-Za-z0-9]", "", scan.stem) or "room"}_1'
    if not ROOM_NAME.fullmatch(room_name):
        raise LabelsInputError(f'--room {room_name!r}: expected <letters or digits>_<number>, '
                               'e.g. hall_1 (an S3DIS room name)')
    if area < 1:
        raise LabelsInputError(f'--area {area}: expected a positive area number')
    check_input_file(scan, 'scan file')
    labels_path = check_output(out / f'{scan.stem}.labels.json', '--out', [document, scan])
    room_dir = check_output(out / f'Area_{area}' / room_name, '--room', folder=True)
    points = read_scan(scan)
    read = read_document(document, freecadcmd, timeout)
    boxes = read['boxes']
    if not boxes and not read['reviewed']:  # reviewed and empty: a room without the classes
        raise LabelsInputError(f'{document}: the document holds no synthdet part to label '
                               '(mark it reviewed if the room holds none of the classes)')
    names = instance_names(boxes, str(document))
    owners = point_owners(points[:, :3], boxes, str(document))
    repeated, warnings = shadowed_boxes(points[:, :3], boxes, owners, str(document))
    elements = background_elements(points[:, :3], read['room'])
    for index, name in enumerate(names):
        elements[owners == index] = name
    write_s3dis_room(room_dir, points, elements,
                     {names[index]: chunk for index, chunk in repeated.items()})
    write_labels(labels_path, labels_document(read, scan))
    counts = {
        name: sum(box['class'] == name for box in boxes)
        for name in dict.fromkeys(box['class'] for box in boxes)
    }
    return {
        'labels': str(labels_path),
        'room_dir': str(room_dir),
        'boxes': counts,
        'points': int(len(points)),
        'object_points': int((owners >= 0).sum()),
        'reviewed': read['reviewed'],
        'warnings': warnings
    }


def summary_line(summary: dict) -> str:
    """One line: what was written."""
    boxes = ', '.join(f'{count} {name}' for name, count in summary['boxes'].items()) or \
        'no object'
    return (f'wrote {summary["labels"]} ({boxes}) and {summary["room_dir"]} '
            f'({summary["object_points"]} of {summary["points"]} points in boxes)'
            f'{"" if summary["reviewed"] else "; the document is not marked reviewed"}')
