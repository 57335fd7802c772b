"""Builds the room and the detections into a FreeCAD document (runs inside FreeCAD).

Groups: ``Room`` (parameter sheet, floor sketch and face, walls), ``Furniture`` (table, chair,
sofa, bookcase), ``Equipment`` (everything else) and, hidden, ``Alternatives`` (the other
classes detected on the same box as an object). Lengths are millimetres.
"""
import os
from contextlib import contextmanager
from typing import Iterator

import FreeCAD as App
import Part
import Sketcher

from . import appearance, arrangement, library

FURNITURE_CLASSES = ('table', 'chair', 'sofa', 'bookcase')
STEP_SUFFIXES = ('.step', '.stp')
DOCUMENT_PREFERENCES = 'User parameter:BaseApp/Preferences/Document'


@contextmanager
def labels_checked_once(doc) -> Iterator[None]:
    """Within the block FreeCAD does not check each new label against all others (that check
    makes building n objects take time in n squared); afterwards the labels are made unique in
    one pass, as FreeCAD would (a repeated label gets 001, 002, ...). The user's preference
    (``DuplicateLabels``) is restored."""
    preferences = App.ParamGet(DOCUMENT_PREFERENCES)
    allowed = preferences.GetBool('DuplicateLabels', False)
    preferences.SetBool('DuplicateLabels', True)
    try:
        yield
        if not allowed:
            _make_labels_unique(doc)
    finally:
        if not allowed:
            preferences.RemBool('DuplicateLabels')


def _make_labels_unique(doc) -> None:
    used = set()
    for obj in doc.Objects:
        label = obj.Label
        if label in used:
            number = 1
            while f'{label}{number:03d}' in used:
                number += 1
            label = f'{label}{number:03d}'
            obj.Label = label
        used.add(label)


def document_group(doc, name: str):
    """The document's group ``name``, added when it has none."""
    existing = doc.getObject(name)
    if existing is not None and existing.TypeId == 'App::DocumentObjectGroup':
        return existing
    return doc.addObject('App::DocumentObjectGroup', name)


def build_room(doc, corners: dict, wall_thickness: float, group, look):
    """Floor face from the corner sketch, and walls offset outwards and extruded to the ceiling.

    ``RoomParameters`` (a sheet) holds ``height``, ``wall_thickness`` and ``floor_z``; the
    sketch, offset and extrusion are bound to it by expressions. The ``Room`` group records
    whether the floor is approximate (``ApproximateFloor``: the corner finder could not trace
    the outline, the floor is the points' footprint) and whether the scan showed a ceiling
    (``CeilingFound``: if not, the walls have the default height). Returns the sheet.
    """
    sheet = doc.addObject('Spreadsheet::Sheet', 'RoomParameters')
    sheet.setColumnWidth('A', library.LABEL_COLUMN_WIDTH)
    group.addObject(sheet)
    rows = (('height', corners['ceiling_z'] - corners['floor_z'], 'room height'),
            ('wall_thickness', wall_thickness, 'wall thickness'), ('floor_z', corners['floor_z'],
                                                                   'floor level'))
    for row, (alias, metres, description) in enumerate(rows, start=1):
        sheet.set(f'A{row}', description)
        sheet.set(f'B{row}', f'={1000.0 * metres:.3f} mm')
        sheet.setAlias(f'B{row}', alias)
    quality = corners.get('quality', {})
    approximate = bool(quality.get('approximate_floor', 0.0))
    for prop, type_name, value in (
        ('SourceScan', 'App::PropertyString', corners['scan']),
        ('CornerCount', 'App::PropertyInteger', len(corners['corners'])),
        ('ApproximateFloor', 'App::PropertyBool', approximate),
        ('CeilingFound', 'App::PropertyBool', bool(quality.get('ceiling_found', 1.0))),
    ):
        group.addProperty(type_name, prop, 'Synthdet', 'from the corners file')
        setattr(group, prop, value)

    sketch = doc.addObject('Sketcher::SketchObject', 'FloorSketch')
    group.addObject(sketch)
    points = [App.Vector(1000.0 * x, 1000.0 * y, 0.0) for x, y in corners['corners']]
    count = len(points)
    # all edges, then all constraints, in one call each: the sketch is solved once, not once
    # per constraint (a thousand corners took minutes that way)
    sketch.addGeometry([Part.LineSegment(points[index], points[(index + 1) % count])
                        for index in range(count)], False)
    sketch.addConstraint([Sketcher.Constraint('Coincident', index, 2, (index + 1) % count, 1)
                          for index in range(count)])
    sketch.setExpression('.Placement.Base.z', f'{sheet.Name}.floor_z')

    floor = doc.addObject('Part::Face', 'Floor')
    floor.Sources = [sketch]
    if approximate:
        floor.Label = 'Floor (approximate)'
    outline = doc.addObject('Part::Offset2D', 'WallOutline')
    outline.Source = sketch
    outline.Join = 'Intersection'
    outline.setExpression('Value', f'{sheet.Name}.wall_thickness')
    profile = doc.addObject('Part::Face', 'WallProfile')
    profile.Sources = [sketch, outline]
    walls = doc.addObject('Part::Extrusion', 'Walls')
    walls.Base = profile
    walls.DirMode = 'Custom'
    walls.Dir = App.Vector(0, 0, 1)
    walls.Solid = True
    walls.setExpression('LengthFwd', f'{sheet.Name}.height')
    for obj in (floor, outline, profile, walls):
        group.addObject(obj)
    for obj in (sketch, outline, profile):
        obj.Visibility = False
    look.paint(floor, appearance.class_color('floor'))
    look.paint(walls, appearance.class_color('wall'), appearance.WALL_TRANSPARENCY)
    return sheet


def find_step_models(library_dir: str | None) -> dict[str, str]:
    """Map class name -> STEP path for ``<class>.step``/``.stp`` files in ``library_dir``.

    The folder is listed and matched by name; no path is ever built from a class name.
    """
    if not library_dir:
        return {}
    if not os.path.isdir(library_dir):
        raise ValueError(f'library folder {library_dir!r} does not exist')
    models = {}
    for entry in sorted(os.listdir(library_dir)):
        stem, suffix = os.path.splitext(entry)
        path = os.path.join(library_dir, entry)
        if suffix.lower() in STEP_SUFFIXES and os.path.isfile(path):
            models.setdefault(stem, path)
    return models


def _import_step(doc, class_name: str, path: str, group):
    shape = Part.read(path)
    if shape.isNull() or shape.BoundBox.DiagonalLength <= 0.0:
        raise ValueError(f'{path}: the STEP file holds no geometry')
    obj = doc.addObject('Part::Feature', 'LibraryModel')
    obj.Label = f'{class_name} (STEP)'
    obj.Shape = shape
    obj.addProperty('App::PropertyString', 'SourceFile', 'Synthdet', 'imported STEP file')
    obj.SourceFile = path
    obj.Visibility = False
    group.addObject(obj)
    return obj


def _stand(container, placed, containers: dict, room_sheet) -> None:
    """Bind the part's base height to what it stands on, so that it follows edits of the
    table's height (or of the room's ``floor_z``)."""
    support = placed.support
    if support is not None and support in containers:
        table = containers[support]
        container.setExpression('.Placement.Base.z',
                                f'{table.Name}.Placement.Base.z + {table.Name}.Height')
    elif support is None and room_sheet is not None:
        container.setExpression('.Placement.Base.z', f'{room_sheet.Name}.floor_z')


def _add_members(group, objects: list) -> None:
    """Add ``objects`` to ``group`` in one step: FreeCAD checks every member of a group each
    time one is added (each object may be in one group only), so adding them one by one would
    take time in the square of their number."""
    if objects:
        group.addObjects(objects)


def _paint_model(look, part) -> None:
    look.paint(part, appearance.class_color(part.DetectedClass))


def import_detections(doc,
                      predictions: dict,
                      corners: dict | None,
                      library_dir: str | None,
                      min_score: float,
                      wall_thickness: float,
                      look=None) -> dict:
    """Add the room (if corners are given) and every detection scoring >= ``min_score``.

    Detections are merged, stood on the floor or their table, oriented and kept inside the
    walls by ``arrangement``; ``look`` (an ``appearance.Look``) collects the colors. Returns a
    report: ``objects`` (name, label, class, group, model, stands_on, orientation,
    alternatives), ``warnings`` and ``skipped_low_score``.
    """
    with labels_checked_once(doc):
        return _build(doc, predictions, corners, library_dir, min_score, wall_thickness, look)


def _build(doc, predictions: dict, corners: dict | None, library_dir: str | None, min_score: float,
           wall_thickness: float, look) -> dict:
    look = look if look is not None else appearance.Look()
    room = document_group(doc, 'Room')
    furniture = document_group(doc, 'Furniture')
    equipment = document_group(doc, 'Equipment')
    room_sheet = None
    if corners is not None:
        room_sheet = build_room(doc, corners, wall_thickness, room, look)
    kept = [d for d in predictions['detections'] if d['score'] >= min_score]
    skipped = len(predictions['detections']) - len(kept)
    placed_items, warnings = arrangement.arrange(kept, corners)
    if corners is not None and corners.get('quality', {}).get('approximate_floor', 0.0):
        warnings.append('the floor is approximate (the points\' footprint, no traced room '
                        'outline): check the walls (Room.ApproximateFloor)')
    step_paths = find_step_models(library_dir)
    step_objects = {}
    containers = {}
    warned = set()
    next_numbers = {}

    def build(placed):
        class_name = placed.class_name
        library_object = None
        if class_name in step_paths:
            if class_name not in step_objects:
                step_objects[class_name] = _import_step(doc, class_name, step_paths[class_name],
                                                        document_group(doc, 'Library'))
            library_object = step_objects[class_name]
        container, kind = library.add_detection(doc, placed, predictions['scan'],
                                                predictions['model'], library_object, next_numbers)
        if kind == 'box' and class_name not in warned:
            warned.add(class_name)
            warnings.append(f'no CAD model for class {class_name!r}: placed labelled boxes')
        _stand(container, placed, containers, room_sheet)
        _paint_model(look, container)
        containers[placed] = container
        return container, kind

    objects = []
    tables_first = sorted(placed_items, key=lambda item: item.class_name != 'table')
    built = {placed: build(placed) for placed in tables_first}
    members = {furniture: [], equipment: []}  # each group filled at once: see _add_members
    hidden_alternatives = []
    for placed in placed_items:
        container, kind = built[placed]
        group = furniture if placed.class_name in FURNITURE_CLASSES else equipment
        members[group].append(container)
        alternatives = _linked_alternatives(container, placed, build)
        hidden_alternatives.extend(alternatives)
        objects.append({
            'name': container.Name,
            'label': container.Label,
            'class': placed.class_name,
            'group': group.Name,
            'model': kind,
            'stands_on': container.StandsOn,
            'orientation': placed.orientation,
            'alternatives': [alternative.Label for alternative in alternatives],
        })
    _fill_groups_and_recompute(doc, members, hidden_alternatives)
    return {'objects': objects, 'warnings': warnings, 'skipped_low_score': skipped}


def _linked_alternatives(container, placed, build) -> list:
    """The other classes detected on the box of ``placed``, built (``build``) and hidden, and
    linked from its ``container``'s ``Alternatives`` property."""
    alternatives = []
    for other in placed.alternatives:
        alternative, _ = build(other)
        alternative.Visibility = False
        alternatives.append(alternative)
    if alternatives:
        container.addProperty(
            'App::PropertyLinkList', 'Alternatives', 'Synthdet',
            'other classes detected on this box (hidden in the '
            'Alternatives group: show one and hide this part to switch)')
        container.Alternatives = alternatives
    return alternatives


def _fill_groups_and_recompute(doc, members: dict, hidden_alternatives: list) -> None:
    """Fill every group with its ``members`` at once, the hidden alternatives into a hidden
    Alternatives group, and recompute; raise if FreeCAD cannot."""
    for group, containers_of_group in members.items():
        _add_members(group, containers_of_group)
    if hidden_alternatives:
        _add_members(document_group(doc, 'Alternatives'), hidden_alternatives)
    if doc.getObject('Alternatives') is not None:
        doc.getObject('Alternatives').Visibility = False
    doc.recompute()
    broken = [obj.Name for obj in doc.Objects if not obj.isValid()]
    if broken:
        raise RuntimeError(f'FreeCAD could not recompute: {", ".join(broken)}')
