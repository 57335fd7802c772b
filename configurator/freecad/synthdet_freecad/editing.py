"""Correcting a synthdet document by hand: add a part, mark the document reviewed (runs inside
FreeCAD, GUI or headless).

An added part is built like an imported detection (``library.add_detection``: the same
parametric model, dimensions and ``Synthdet`` properties, score 1, source model
``added by hand``) with the class's typical size, standing on the room's floor (its base height
bound to the room's ``floor_z`` cell). ``macro`` offers both in the GUI.
"""
import FreeCAD as App

from . import arrangement, document, labels, library

ADDED_BY_HAND = 'added by hand'
# a new part's size (length, width, height in metres) per class; other classes get a 1 m cube
DEFAULT_SIZES = {
    'table': (1.4, 0.8, 0.75),
    'chair': (0.5, 0.5, 0.9),
    'sofa': (1.9, 0.9, 0.85),
    'bookcase': (0.9, 0.35, 1.9),
    'yumi': (library.YUMI_REST_ACROSS, library.YUMI_REST_DEPTH, library.YUMI_HEIGHT),
    '3dprinter': (0.5, 0.5, 0.6),
}
DEFAULT_SIZE = (1.0, 1.0, 1.0)
ADDABLE_CLASSES = tuple(DEFAULT_SIZES)


def add_part(doc,
             class_name: str,
             x: float,
             y: float,
             yaw: float = 0.0,
             size: tuple[float, float, float] | None = None):
    """Add a parametric part of ``class_name`` whose base centre is at (x, y) metres, turned
    by ``yaw`` radians, on the floor (z 0 without a room); returns it after a recompute."""
    if not class_name or not class_name.strip():
        raise ValueError('a part needs a class name')
    length, width, height = size or DEFAULT_SIZES.get(class_name, DEFAULT_SIZE)
    sheet = labels.room_sheet(doc)
    floor_z = floor_height(doc)
    count = sum(1 for part in labels.synthdet_parts(doc) if part.DetectedClass == class_name)
    detection = {
        'class': class_name,
        'score': 1.0,
        'center': [x, y, floor_z + height / 2.0],
        'size': [length, width, height],
        'yaw': yaw,
    }
    placed = arrangement.Placed(detection, f'{class_name} {count + 1} ({ADDED_BY_HAND})')
    with document.labels_checked_once(doc):
        scan = labels.source_scan(labels.synthdet_parts(doc))
        part, _ = library.add_detection(doc, placed, scan, ADDED_BY_HAND)
    part.Orientation = ADDED_BY_HAND
    if sheet is not None:
        part.setExpression('.Placement.Base.z', f'{sheet.Name}.floor_z')
    group_name = 'Furniture' if class_name in document.FURNITURE_CLASSES else 'Equipment'
    document.document_group(doc, group_name).addObject(part)
    doc.recompute()
    return part


def view_point(view, floor_z: float) -> tuple[float, float]:
    """Where the 3D view's centre ray meets the floor plane, in metres (GUI only)."""
    from pivy import coin
    camera = view.getCameraNode()
    origin = App.Vector(*camera.position.getValue().getValue())
    ray = App.Vector(*camera.orientation.getValue().multVec(coin.SbVec3f(0, 0, -1)).getValue())
    if abs(ray.z) < 1e-9:
        return origin.x / 1000.0, origin.y / 1000.0
    t = (1000.0 * floor_z - origin.z) / ray.z
    return (origin.x + t * ray.x) / 1000.0, (origin.y + t * ray.y) / 1000.0


def set_reviewed(doc, reviewed: bool = True) -> None:
    """Mark the document as reviewed (or not) in its metadata."""
    meta = dict(doc.Meta)
    meta[labels.REVIEWED_KEY] = 'true' if reviewed else 'false'
    doc.Meta = meta


def is_reviewed(doc) -> bool:
    """Whether the document is marked reviewed."""
    return doc.Meta.get(labels.REVIEWED_KEY, '') == 'true'


def floor_height(doc) -> float:
    """The room's floor height in metres (0 without a room)."""
    sheet = labels.room_sheet(doc)
    return sheet.get('floor_z').Value / 1000.0 if sheet is not None else 0.0
