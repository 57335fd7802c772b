"""Do a generated room's annotations describe its objects? (``tools/check_annotations.py``)

A detector's true boxes are the extents of each instance's annotated points (mmdet3d's S3DIS
converter), so a labelling rule that gives an object points off its surface (for example a laser
scanner's mixed pixels, which lie in the air between an object and the wall behind it) stretches
its box. The generator knows each object's real box (``meta.json``): :func:`object_fit` compares
the annotated points with it, in the box's own axes. It also measures how much of the object an
annotation covers: a sensor that sees an object from one side only annotates part of it, and its
true box is that part.
"""
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from synthdet.classes import DETECTION_CLASSES
from synthdet.contracts import read_room
from synthdet.geometry import rotation_z
from synthdet.point_text import read_point_file

TOLERANCE = 0.05  # metres a box grows per side: 5 sigma of a 1 cm range noise, and rounding
MAX_OUTSIDE = 0.01  # share of an object's points allowed outside: noise tails, not a rule


@dataclass
class ObjectFit:
    """One annotated object against its ``meta.json`` box."""

    room: str
    sensor: str
    instance: str
    class_name: str
    points: int
    extent_ratio: float  # largest horizontal extent of the points / the box's, in box axes
    outside: float  # share of the points outside the box grown by the tolerance
    coverage: float  # share of the box's volume inside the points' extents, in box axes


def object_fit(points: np.ndarray, box: dict,
               tolerance: float) -> tuple[float, float, float]:
    """``(extent ratio, share outside, coverage)`` of ``points`` (N, 3) against a ``meta.json``
    box (gravity centre, size, yaw about z), with the box grown by ``tolerance`` metres per side
    for the share outside. Coverage is the share of the box's volume that the points' extents (in
    the box's axes) enclose: 1.0 for an object seen whole, about 0.5 for one seen to half its
    depth; it is the IoU of the annotation's box with the object's when no point lies outside."""
    local = (points - np.asarray(box['center'])) @ rotation_z(box['yaw'])  # into the box's axes
    size = np.asarray(box['size'], dtype=float)
    low, high = local.min(axis=0), local.max(axis=0)
    ratio = float(np.max((high - low)[:2] / size[:2]))
    outside = np.any(np.abs(local) > size / 2 + tolerance, axis=1)
    overlap = np.clip(np.minimum(high, size / 2) - np.maximum(low, -size / 2), 0.0, None)
    return ratio, float(outside.mean()), float(np.prod(overlap / size))


def check_room(room_dir: Path, tolerance: float = TOLERANCE) -> list[ObjectFit]:
    """Every detection-class object of a generated room with an annotation file."""
    meta = read_room(room_dir / 'meta.json')
    sensor = meta.get('generator', {}).get('sensor', {}).get('model', 'paper')
    fits = []
    for obj in meta['objects']:
        annotation = room_dir / 'Annotations' / f'{obj["instance"]}.txt'
        if obj['class'] not in DETECTION_CLASSES or not annotation.is_file():
            continue
        points, _ = read_point_file(annotation)
        ratio, outside, coverage = object_fit(points[:, :3], obj['box'], tolerance)
        fits.append(
            ObjectFit(room_dir.name, sensor, obj['instance'], obj['class'], len(points), ratio,
                      outside, coverage))
    return fits


def summarize(fits: list[ObjectFit]) -> list[dict]:
    """Per sensor and class: objects, median / 90th-percentile extent ratio and share outside,
    how many objects have any point outside, the median coverage and the share of objects
    covered less than half (whose true box a prediction of the whole object misses at IoU
    0.5)."""
    groups: dict[tuple[str, str], list[ObjectFit]] = {}
    for fit in fits:
        groups.setdefault((fit.sensor, fit.class_name), []).append(fit)
    rows = []
    for (sensor, cls), group in sorted(groups.items()):
        ratio = np.array([f.extent_ratio for f in group])
        outside = np.array([f.outside for f in group])
        coverage = np.array([f.coverage for f in group])
        rows.append({
            'sensor': sensor,
            'class': cls,
            'objects': len(group),
            'extent_median': float(np.median(ratio)),
            'extent_p90': float(np.percentile(ratio, 90)),
            'outside_median': float(np.median(outside)),
            'outside_p90': float(np.percentile(outside, 90)),
            'objects_with_points_outside': int(np.count_nonzero(outside > 0)),
            'coverage_median': float(np.median(coverage)),
            'covered_below_half': float(np.mean(coverage < 0.5)),
        })
    return rows


def format_summary(rows: list[dict]) -> str:
    """The rows of :func:`summarize` as aligned text."""
    header = (f'{"sensor":13s}{"class":11s}{"objects":>8s}{"extent":>8s}{"p90":>7s}'
              f'{"outside":>9s}{"p90":>7s}{"with":>6s}{"coverage":>10s}{"<0.5":>6s}')
    lines = [header]
    for r in rows:
        lines.append(f'{r["sensor"]:13s}{r["class"]:11s}{r["objects"]:8d}{r["extent_median"]:8.2f}'
                     f'{r["extent_p90"]:7.2f}{r["outside_median"]:9.3f}{r["outside_p90"]:7.3f}'
                     f'{r["objects_with_points_outside"]:6d}{r["coverage_median"]:10.2f}'
                     f'{r["covered_below_half"]:6.2f}')
    return '\n'.join(lines)


def offenders(fits: list[ObjectFit], max_outside: float = MAX_OUTSIDE) -> list[ObjectFit]:
    """The objects with more than ``max_outside`` of their points outside their box."""
    return [fit for fit in fits if fit.outside > max_outside]


def describe(fit: ObjectFit) -> str:
    """One line naming an object and how far its annotation leaves its box."""
    return (f'{fit.room}/{fit.instance} ({fit.sensor}): {fit.outside:.1%} of {fit.points} '
            f'points outside, extent x{fit.extent_ratio:.2f}')
