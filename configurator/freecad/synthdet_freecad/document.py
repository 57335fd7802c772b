"""Builds the room and the detections into a FreeCAD document (runs inside FreeCAD).

Groups: ``Room`` (parameter sheet, floor sketch and face, walls), ``Furniture`` (table, chair,
sofa, bookcase) and ``Equipment`` (everything else). Lengths are millimetres.
"""
import os

import FreeCAD as App
import Part
import Sketcher

from . import library

FURNITURE_CLASSES = ('table', 'chair', 'sofa', 'bookcase')
STEP_SUFFIXES = ('.step', '.stp')


def _group(doc, name: str):
    existing = doc.getObject(name)
    if existing is not None and existing.TypeId == 'App::DocumentObjectGroup':
        return existing
    return doc.addObject('App::DocumentObjectGroup', name)


def build_room(doc, corners: dict, wall_thickness: float, group) -> None:
    """Floor face from the corner sketch, and walls offset outwards and extruded to the ceiling.

    ``RoomParameters`` (a sheet) holds ``height``, ``wall_thickness`` and ``floor_z``; the
    sketch, offset and extrusion are bound to it by expressions.
    """
    sheet = doc.addObject('Spreadsheet::Sheet', 'RoomParameters')
    group.addObject(sheet)
    rows = (('height', corners['ceiling_z'] - corners['floor_z'], 'room height'),
            ('wall_thickness', wall_thickness, 'wall thickness'), ('floor_z', corners['floor_z'],
                                                                   'floor level'))
    for row, (alias, metres, description) in enumerate(rows, start=1):
        sheet.set(f'A{row}', description)
        sheet.set(f'B{row}', f'={1000.0 * metres:.3f} mm')
        sheet.setAlias(f'B{row}', alias)
    for prop, type_name, value in (('SourceScan', 'App::PropertyString',
                                    corners['scan']), ('CornerCount', 'App::PropertyInteger',
                                                       len(corners['corners']))):
        group.addProperty(type_name, prop, 'Synthdet', 'from the corners file')
        setattr(group, prop, value)

    sketch = doc.addObject('Sketcher::SketchObject', 'FloorSketch')
    group.addObject(sketch)
    points = [App.Vector(1000.0 * x, 1000.0 * y, 0.0) for x, y in corners['corners']]
    count = len(points)
    for index in range(count):
        sketch.addGeometry(Part.LineSegment(points[index], points[(index + 1) % count]), False)
    for index in range(count):
        sketch.addConstraint(Sketcher.Constraint('Coincident', index, 2, (index + 1) % count, 1))
    sketch.setExpression('.Placement.Base.z', f'{sheet.Name}.floor_z')

    floor = doc.addObject('Part::Face', 'Floor')
    floor.Sources = [sketch]
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


def import_detections(doc, predictions: dict, corners: dict | None, library_dir: str | None,
                      min_score: float, wall_thickness: float) -> dict:
    """Add the room (if corners are given) and every detection scoring >= ``min_score``.

    Returns a report: ``objects`` (name, label, class, group, model), ``warnings`` and
    ``skipped_low_score``.
    """
    warnings = []
    room = _group(doc, 'Room')
    furniture = _group(doc, 'Furniture')
    equipment = _group(doc, 'Equipment')
    if corners is not None:
        build_room(doc, corners, wall_thickness, room)
    step_paths = find_step_models(library_dir)
    step_objects = {}
    library_group = None
    objects = []
    skipped = 0
    counts = {}
    for detection in predictions['detections']:
        if detection['score'] < min_score:
            skipped += 1
            continue
        class_name = detection['class']
        counts[class_name] = counts.get(class_name, 0) + 1
        library_object = None
        if class_name in step_paths:
            if class_name not in step_objects:
                if library_group is None:
                    library_group = _group(doc, 'Library')
                step_objects[class_name] = _import_step(doc, class_name, step_paths[class_name],
                                                        library_group)
            library_object = step_objects[class_name]
        detection = dict(detection, scan=predictions['scan'], model=predictions['model'])
        container, kind = library.add_detection(doc, detection, counts[class_name], library_object)
        if kind == 'box' and counts[class_name] == 1:
            warnings.append(f'no CAD model for class {class_name!r}: placed labelled boxes')
        group = furniture if class_name in FURNITURE_CLASSES else equipment
        group.addObject(container)
        objects.append({
            'name': container.Name,
            'label': container.Label,
            'class': class_name,
            'group': group.Name,
            'model': kind
        })
    doc.recompute()
    broken = [obj.Name for obj in doc.Objects if not obj.isValid()]
    if broken:
        raise RuntimeError(f'FreeCAD could not recompute: {", ".join(broken)}')
    return {'objects': objects, 'warnings': warnings, 'skipped_low_score': skipped}
