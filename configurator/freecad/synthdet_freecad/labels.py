"""Read a (corrected) synthdet document back: every counted part's box, and the room (runs
inside FreeCAD).

A synthdet part is any object carrying the ``Synthdet`` property ``DetectedClass`` (whatever
its FreeCAD type); its box is its global placement (the centre of its base, in the scan's own
coordinates, millimetres) turned about z, and its ``Length``, ``Width`` and ``Height``
properties (in a document built before parts had them, the ``length``, ``width`` and ``height``
cells of its parameter sheet). Which parts count:

- a part that is nobody's alternative counts, unless it is hidden while one of its
  alternatives is shown (the user switched to that alternative);
- an alternative (listed in another part's ``Alternatives``) counts only when it is shown and
  the part it is an alternative to is hidden;
- a part in the ``Alternatives`` group that no part lists (the part it was an alternative to
  was deleted) counts only when it is shown.

A deleted part is simply gone (its alternatives follow the rule above); a part added by hand
(``editing.add_part``) is an ordinary part.
The room comes from the group carrying the ``Synthdet`` property ``CornerCount``: its
parameter sheet (``floor_z``, ``height``) and its floor sketch (the corners, in order).
"""
import json
import math
import os

import FreeCAD as App
# standard library only, importable wherever schema's synthdet.contracts is
from synthdet.fcstd_guard import RefusedDocument

# the parts' proxy class: FreeCAD restores a proxy only from a module loaded before the
# document opens (or an installed add-on), and the recompute below needs it
from . import library
from .opening import open_document
from .schema import LABELS_READ_FORMAT as READ_FORMAT

SIZE_PROPERTIES = ('Length', 'Width', 'Height')
SIZE_ALIASES = ('length', 'width', 'height')  # a parameter sheet's cells
REVIEWED_KEY = 'SynthdetReviewed'  # document metadata (Document.Meta): 'true' once reviewed
ENV_READ = 'SYNTHDET_READ'  # headless: the document to read (the result goes to SYNTHDET_RESULT)
MAX_TILT_DEG = 0.5  # a part turned further off the vertical is not a box standing upright
ALTERNATIVES_GROUP = 'Alternatives'  # the hidden group the document's alternatives are built in


class NotSynthdet(ValueError):
    """The document holds nothing synthdet built, or a part that cannot be read as a box."""


def _synthdet_property(obj, name: str) -> bool:
    return name in obj.PropertiesList and obj.getGroupOfProperty(name) == 'Synthdet'


def synthdet_parts(doc) -> list:
    """Every object of ``doc`` that is a synthdet part (``Synthdet`` property DetectedClass)."""
    return [obj for obj in doc.Objects if _synthdet_property(obj, 'DetectedClass')]


def counted_parts(parts: list) -> list:
    """The parts that are labels, by the visibility rule of the module doc, in document order."""
    winner_of = {}
    for part in parts:
        if _synthdet_property(part, 'Alternatives'):
            for alternative in part.Alternatives:
                winner_of[alternative.Name] = part
    shown_alternative = {
        winner_of[part.Name].Name
        for part in parts if part.Name in winner_of and part.Visibility
    }
    counted = []
    for part in parts:
        winner = winner_of.get(part.Name)
        if winner is not None:
            if part.Visibility and not winner.Visibility:
                counted.append(part)
        elif _in_alternatives_group(part):
            if part.Visibility:  # its part was deleted: hidden, it was never switched in
                counted.append(part)
        elif part.Visibility or part.Name not in shown_alternative:
            counted.append(part)
    return counted


def _in_alternatives_group(part) -> bool:
    return any(obj.Name == ALTERNATIVES_GROUP and obj.TypeId == 'App::DocumentObjectGroup'
               for obj in part.InList)


def part_children(part) -> list:
    """The objects a part holds, whatever its type: a group's ``Group``, a link group's
    ``ElementList``."""
    for prop in ('Group', 'ElementList'):
        if prop in part.PropertiesList:
            return list(getattr(part, prop))
    return []


def parameter_sheet(doc, part):
    """The spreadsheet holding the part's size cells: among its children, else by name."""
    candidates = part_children(part) + [doc.getObject(f'{part.Name}_Parameters')]
    for obj in candidates:
        if obj is not None and obj.TypeId == 'Spreadsheet::Sheet' and \
                obj.getCellFromAlias('length'):
            return obj
    raise NotSynthdet(f'part {part.Label!r} has no parameter sheet with a length cell')


def _positive(value, name: str, what: str) -> float:
    millimetres = value.Value if hasattr(value, 'Value') else float(value)
    if not (math.isfinite(millimetres) and millimetres > 0.0):
        raise NotSynthdet(f'{what}: {name} is {millimetres} mm, expected a positive length')
    return millimetres


def _millimetres(sheet, alias: str, what: str) -> float:
    return _positive(sheet.get(alias), alias, what)


def part_size(doc, part) -> list[float]:
    """The part's length, width and height in mm: its own properties, else its sheet's."""
    what = f'part {part.Label!r}'
    if all(name in part.PropertiesList for name in SIZE_PROPERTIES):
        return [_positive(getattr(part, name), name, what) for name in SIZE_PROPERTIES]
    sheet = parameter_sheet(doc, part)
    return [_millimetres(sheet, alias, what) for alias in SIZE_ALIASES]


def part_box(doc, part) -> dict:
    """The part's label box in metres and radians: class, centre, size, yaw (and its name)."""
    size = part_size(doc, part)
    # a part in the tree's groups (no placement of their own) or in an App::Part
    placement = part.getGlobalPlacement() if hasattr(part, 'getGlobalPlacement') \
        else part.Placement
    up = placement.Rotation.multVec(App.Vector(0, 0, 1))
    if up.z < math.cos(math.radians(MAX_TILT_DEG)):
        raise NotSynthdet(f'part {part.Label!r} is tilted {math.degrees(math.acos(up.z)):.1f} '
                          'degrees off the vertical: a label box stands upright')
    axis = placement.Rotation.multVec(App.Vector(1, 0, 0))
    base = placement.Base
    return {
        'name': part.Name,
        'label': part.Label,
        'class': part.DetectedClass,
        'center': [base.x / 1000.0, base.y / 1000.0, (base.z + size[2] / 2.0) / 1000.0],
        'size': [value / 1000.0 for value in size],
        'yaw': math.atan2(axis.y, axis.x),
    }


def _room_children(doc) -> list:
    """The objects of the room group (the ``Synthdet`` property CornerCount); [] without one."""
    groups = [obj for obj in doc.Objects if _synthdet_property(obj, 'CornerCount')]
    return part_children(groups[0]) if groups else []


def room_sheet(doc):
    """The room's parameter sheet (the one with a ``floor_z`` cell), or None."""
    return next((child for child in _room_children(doc) if child.TypeId == 'Spreadsheet::Sheet'
                 and child.getCellFromAlias('floor_z')), None)


def room_outline(doc) -> dict | None:
    """The room's corners (metres, sketch order), floor and ceiling heights, or None."""
    sheet = room_sheet(doc)
    sketches = [c for c in _room_children(doc) if c.TypeId == 'Sketcher::SketchObject']
    if sheet is None or not sketches:
        return None
    floor_z = sheet.get('floor_z')
    floor_z = (floor_z.Value if hasattr(floor_z, 'Value') else float(floor_z)) / 1000.0
    height = _millimetres(sheet, 'height', 'room') / 1000.0
    sketch = sketches[0]
    placement = sketch.getGlobalPlacement()
    corners = []
    for geometry in sketch.Geometry:
        if hasattr(geometry, 'StartPoint'):
            point = placement.multVec(geometry.StartPoint)
            corners.append([point.x / 1000.0, point.y / 1000.0])
    return {'corners': corners, 'floor_z': floor_z, 'ceiling_z': floor_z + height}


def read_document(path: str) -> dict:
    """Open the document at ``path`` (checked first, read only: never saved) and return its
    labels and room.

    Raises ``RefusedDocument`` for a document FreeCAD would run code or open other files for,
    ``NotSynthdet`` when it holds no synthdet part or room, or a part that is no box.
    """
    doc = open_document(path)
    try:
        library.restore_proxies(doc)
        doc.recompute()  # a cell edited without a recompute gives the sizes the user sees
        parts = synthdet_parts(doc)
        room = room_outline(doc)
        if not parts and room is None:
            raise NotSynthdet('not a synthdet document: no part has synthdet\'s '
                              'DetectedClass property and there is no synthdet room')
        boxes = [part_box(doc, part) for part in counted_parts(parts)]
        return {
            'format': READ_FORMAT,
            'boxes': boxes,
            'room': room,
            'reviewed': doc.Meta.get(REVIEWED_KEY, '') == 'true',
            'scan': source_scan(parts),
        }
    finally:
        App.closeDocument(doc.Name)


def source_scan(parts: list) -> str:
    """The scan the parts were detected in (the first part naming one), else ''."""
    for part in parts:
        if _synthdet_property(part, 'SourceScan') and part.SourceScan:
            return part.SourceScan
    return ''


def run_headless() -> None:
    """Read the document named by ``SYNTHDET_READ`` and write the result JSON (status ``ok``,
    or ``error`` with ``kind`` ``input`` for a document that is refused or not synthdet's)."""
    result_path = os.environ['SYNTHDET_RESULT']
    try:
        result = dict(read_document(os.environ[ENV_READ]), status='ok', error=None)
    except (NotSynthdet, RefusedDocument) as error:
        result = {'format': READ_FORMAT, 'status': 'error', 'kind': 'input', 'error': str(error)}
    except Exception as error:  # the process boundary: every failure goes to the result file
        result = {
            'format': READ_FORMAT,
            'status': 'error',
            'kind': 'runtime',
            'error': f'{type(error).__name__}: {error}'
        }
    temporary = f'{result_path}.tmp{os.getpid()}'
    with open(temporary, 'w', encoding='utf-8') as stream:
        json.dump(result, stream, ensure_ascii=False)
    os.replace(temporary, result_path)
