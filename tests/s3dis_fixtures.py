"""Small, real S3DIS-format areas for tests (pure numpy, no Blender).

Each room is a box-shaped space with floor, ceiling and four walls, some clutter and
non-overlapping box-shaped objects. Every object class has a typical size, shape and
color so that a detector can tell the classes apart. Files follow the S3DIS layout:
``Stanford3dDataset_v1.2_Aligned_Version/Area_<n>/<roomtype>_<k>/Annotations/<class>_<i>.txt``
with one ``x y z r g b`` line per point, and ``<room>.txt`` holds all the room's points.
"""
from pathlib import Path
from typing import Sequence

import numpy as np

from projects.synthdet.datasets.s3dis_repairs import KNOWN_STRAY_BYTES

S3DIS_DIR = 'Stanford3dDataset_v1.2_Aligned_Version'
# objects of the real S3DIS's classes, and `stairs`, which a few of its rooms use
S3DIS_OBJECTS = ('table', 'chair', 'sofa', 'bookcase', 'board', 'beam', 'column', 'window', 'door',
                 'stairs')
# the known defect of the real S3DIS: a stray byte in this file (see s3dis_repairs.py)
HALLWAY_CEILING = ('Area_5', 'hallway_6', 'Annotations', 'ceiling_1.txt')
STRAY_OFFSET = KNOWN_STRAY_BYTES[HALLWAY_CEILING]
STRAY_LINE = 180389
STRAY_POINT = [1.5, 5.25, 2.75, 210.0, 211.0, 212.0]
ROOM_TYPES = ('office', 'lab', 'storage', 'conferenceRoom')

# Parts of each object as (size_x, size_y, size_z, z_bottom) boxes centred on the footprint.
OBJECT_PARTS = {
    'table': [(1.2, 0.7, 0.05, 0.70), (0.06, 0.06, 0.70, 0.0)],  # top + central leg
    'chair': [(0.5, 0.5, 0.45, 0.0), (0.5, 0.08, 0.45, 0.45)],  # seat block + backrest
    'sofa': [(1.8, 0.85, 0.42, 0.0), (1.8, 0.2, 0.40, 0.42)],  # base + back
    'bookcase': [(0.9, 0.35, 1.9, 0.0)],
    'board': [(1.5, 0.05, 1.0, 0.9)],  # a whiteboard on a thin stand
    'yumi': [(0.6, 0.6, 0.75, 0.0), (0.22, 0.22, 0.65, 0.75)],  # tall narrow robot on a pedestal
    '3dprinter': [(0.5, 0.5, 0.55, 0.0)],
    'clutter': [(0.3, 0.3, 0.3, 0.0)],
}
GENERIC_PARTS = [(0.7, 0.7, 0.4, 0.0)]  # any other class name, e.g. 'stairs'

# the RGB of each class's points in the synthetic test rooms (not the drawing palette)
SURFACE_COLORS = {
    'ceiling': (225, 225, 215),
    'floor': (95, 90, 85),
    'wall': (180, 175, 160),
    'table': (140, 90, 50),
    'chair': (200, 40, 40),
    'sofa': (40, 80, 200),
    'bookcase': (120, 60, 160),
    'board': (240, 240, 240),
    'yumi': (250, 200, 0),
    '3dprinter': (30, 30, 30),
    'clutter': (60, 160, 60),
}


def _color(class_name: str) -> np.ndarray:
    if class_name in SURFACE_COLORS:
        return np.array(SURFACE_COLORS[class_name], dtype=np.float64)
    name_bytes = np.frombuffer(class_name.encode().ljust(3, b'_')[:3], dtype=np.uint8)
    return (name_bytes.astype(np.float64) * 37) % 256


def _sample_box_surface(rng: np.random.Generator, lo: np.ndarray, hi: np.ndarray,
                        n: int) -> np.ndarray:
    """Sample n points uniformly on the surface of the axis-aligned box [lo, hi]."""
    size = hi - lo
    face_areas = np.array([size[1] * size[2], size[0] * size[2], size[0] * size[1]]).repeat(2)
    faces = rng.choice(6, size=n, p=face_areas / face_areas.sum())
    points = lo + rng.random((n, 3)) * size
    axis = faces // 2
    points[np.arange(n), axis] = np.where(faces % 2 == 0, lo[axis], hi[axis])
    return points


def _sample_object(rng: np.random.Generator, parts: list, centre_xy: np.ndarray, swap_xy: bool,
                   n: int) -> np.ndarray:
    boxes = []
    for size_x, size_y, size_z, z_bottom in parts:
        half = np.array([size_y, size_x] if swap_xy else [size_x, size_y]) / 2
        boxes.append((np.r_[centre_xy - half, z_bottom], np.r_[centre_xy + half,
                                                               z_bottom + size_z]))
    areas = np.array(
        [2 * (s[0] * s[1] + s[0] * s[2] + s[1] * s[2]) for s in (hi - lo for lo, hi in boxes)])
    counts = np.maximum(1, np.round(n * areas / areas.sum()).astype(int))
    return np.concatenate(
        [_sample_box_surface(rng, lo, hi, k) for (lo, hi), k in zip(boxes, counts)])


def _footprint(parts: list, swap_xy: bool) -> np.ndarray:
    extent = np.max([[p[0], p[1]] for p in parts], axis=0)
    return extent[::-1] if swap_xy else extent


def _place_objects(rng: np.random.Generator,
                   classes: Sequence[str],
                   room_xy: np.ndarray,
                   margin: float = 0.15) -> list[tuple[str, np.ndarray, bool]]:
    """One object per class plus up to three extra ones, without xy overlap (rejection)."""
    wanted = list(classes) + list(rng.choice(list(classes), size=3)) + ['clutter'] * 2
    placed: list[tuple[str, np.ndarray, bool, np.ndarray]] = []
    for class_name in wanted:
        parts = OBJECT_PARTS.get(class_name, GENERIC_PARTS)
        for _ in range(50):
            swap_xy = bool(rng.random() < 0.5)
            half = _footprint(parts, swap_xy) / 2
            if np.any(room_xy - 2 * margin < 2 * half):
                break
            centre = rng.uniform(half + margin, room_xy - half - margin)
            if all(
                    np.any(np.abs(centre - other) >= half + other_half + margin)
                    for _, other, _, other_half in placed):
                placed.append((class_name, centre, swap_xy, half))
                break
    return [(name, centre, swap) for name, centre, swap, _ in placed]


def _write_points(path: Path, points: np.ndarray) -> None:
    rows = np.column_stack([points[:, :3], np.floor(points[:, 3:])])
    path.write_text(('%.3f %.3f %.3f %d %d %d\n' * len(rows)) % tuple(rows.ravel()))


def write_synthetic_area(
    root_path: Path,
    area: int,
    n_rooms: int,
    seed: int,
    classes: Sequence[str] = ('table', 'chair', 'sofa', 'yumi', '3dprinter'),
    points_per_object: int = 800,
    room_size: tuple[float, float, float] = (4.0, 4.0, 3.0)
) -> dict[str, list[dict]]:
    """Write S3DIS-format rooms under
    root_path/Stanford3dDataset_v1.2_Aligned_Version/Area_<area>/ and return
    {room_name: [{'class': str, 'min': [x,y,z], 'max': [x,y,z]}, ...]}
    (the true axis-aligned boxes).

    Boxes are listed for every object of ``classes`` (not for structure or clutter), in the
    room's own written frame (not shifted), and equal the min/max of the written points.
    Instances are numbered per class in placement order (``chair_1``, ``chair_2``, ...).
    """
    rng = np.random.default_rng(seed)
    area_dir = Path(root_path) / S3DIS_DIR / f'Area_{area}'
    length, width, height = room_size
    truth: dict[str, list[dict]] = {}
    for room_index in range(n_rooms):
        room_type = ROOM_TYPES[room_index % len(ROOM_TYPES)]
        room_name = f'{room_type}_{room_index // len(ROOM_TYPES) + 1}'
        ann_dir = area_dir / room_name / 'Annotations'
        ann_dir.mkdir(parents=True, exist_ok=True)
        origin = np.r_[rng.uniform(-20.0, 20.0, 2), rng.uniform(0.0, 1.0)]
        structure = {
            'floor_1': (np.zeros(3), np.array([length, width, 0.0]), 2),
            'ceiling_1': (np.array([0.0, 0.0, height]), np.array([length, width, height]), 2),
            'wall_1': (np.zeros(3), np.array([length, 0.0, height]), 1),
            'wall_2': (np.array([length, 0.0, 0.0]), np.array([length, width, height]), 1),
            'wall_3': (np.array([0.0, width, 0.0]), np.array([length, width, height]), 1),
            'wall_4': (np.zeros(3), np.array([0.0, width, height]), 1),
        }
        annotations: list[tuple[str, np.ndarray]] = []
        for instance, (lo, hi, weight) in structure.items():
            n = weight * points_per_object
            annotations.append((instance, lo + rng.random((n, 3)) * (hi - lo)))
        counters: dict[str, int] = {}
        for class_name, centre, swap_xy in _place_objects(rng, classes, np.array([length, width])):
            counters[class_name] = counters.get(class_name, 0) + 1
            n = points_per_object // 2 if class_name == 'clutter' else points_per_object
            xyz = _sample_object(rng, OBJECT_PARTS.get(class_name, GENERIC_PARTS), centre, swap_xy,
                                 n)
            annotations.append((f'{class_name}_{counters[class_name]}', xyz))
        boxes, room_chunks = [], []
        for instance, xyz in annotations:
            class_name = instance.split('_')[0]
            xyz = xyz + origin
            rgb = np.clip(_color(class_name) + rng.normal(0.0, 6.0, (len(xyz), 3)), 0, 255)
            points = np.column_stack([xyz, rgb])
            _write_points(ann_dir / f'{instance}.txt', points)
            room_chunks.append(points)
            if class_name in classes:
                # '%.3f' rounding is monotonic, so the rounded min/max are the written min/max.
                boxes.append({
                    'class': class_name,
                    'min': [float(f'{v:.3f}') for v in xyz.min(axis=0)],
                    'max': [float(f'{v:.3f}') for v in xyz.max(axis=0)]
                })
        _write_points(area_dir / room_name / f'{room_name}.txt', np.concatenate(room_chunks))
        truth[room_name] = boxes
    return truth


def read_room_scene(root_path: Path, area: int, room: str, boxes: list[dict],
                    classes: Sequence[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A room written by :func:`write_synthetic_area` as detector input: its (N, 6) float32
    points moved so that their minimum corner is the origin, with RGB in 0-1, and its true
    ``boxes`` in that frame as (M, 6) centre and size with their (M,) indices into
    ``classes``."""
    points = np.loadtxt(
        Path(root_path) / S3DIS_DIR / f'Area_{area}' / room / f'{room}.txt', dtype=np.float32)
    shift = points[:, :3].min(axis=0)
    points[:, :3] -= shift
    points[:, 3:] /= 255.0
    lo = np.array([box['min'] for box in boxes]) - shift
    hi = np.array([box['max'] for box in boxes]) - shift
    labels = np.array([classes.index(box['class']) for box in boxes])
    return points, np.concatenate(((lo + hi) / 2, hi - lo), axis=1), labels


def write_hallway_6(data_dir: Path) -> int:
    """``Area_5/hallway_6`` with a ceiling file whose line 180389 has the stray byte at the byte
    offset that mmdet3d repairs, in place of the space after its first number; one chair. Returns
    the number of ceiling points."""
    ann_dir = data_dir / 'Area_5' / 'hallway_6' / 'Annotations'
    ann_dir.mkdir(parents=True)
    # 30- and 31-byte lines so that line 180389 starts 5 bytes before the stray byte
    short, long = b'1.000 1.000 3.000 200 200 200\n', b'10.000 1.000 3.000 200 200 200\n'
    num_long = STRAY_OFFSET - 5 - len(short) * (STRAY_LINE - 1)
    lines = long * num_long + short * (STRAY_LINE - 1 - num_long)
    stray_line = b'1.500\x105.250 2.750 210 211 212\n'
    ceiling = lines + stray_line + short * 10
    assert ceiling[STRAY_OFFSET:STRAY_OFFSET + 1] == b'\x10'
    assert ceiling[:STRAY_OFFSET].count(b'\n') == STRAY_LINE - 1
    (ann_dir / 'ceiling_1.txt').write_bytes(ceiling)
    chair = np.column_stack([np.random.default_rng(0).random((50, 3)), np.full((50, 3), 100)])
    _write_points(ann_dir / 'chair_1.txt', chair)
    return STRAY_LINE + 10
