"""Synthetic room scans with known corners, for the corner tests and benchmark.

A room is a floor polygon (rectangular, L, U or T shaped, or a rectangle with one corner cut
by a non-Manhattan wall) extruded to a ceiling height. Its floor, ceiling and walls are
sampled uniformly (walls with door and window openings), furniture boxes stand inside (some
against walls, hiding the floor and wall behind them), and an optional LiDAR-like noise model
perturbs the points as seen from a scanner position: range noise along the ray, angular
jitter across it, random dropout, dropout patches and outliers.
The whole room is then rotated and translated at random, so walls are not axis-aligned.
"""
from __future__ import annotations
import math
from dataclasses import dataclass

import numpy as np

SHAPES = ('rect', 'L', 'U', 'T', 'chamfer')


@dataclass(frozen=True)
class NoiseModel:
    """LiDAR-like perturbations; lengths in metres, angles in radians."""

    range_sigma: float = 0.01  # along the scanner ray
    angular_sigma: float = 0.0005  # across the ray (0.03 degree)
    dropout: float = 0.1  # fraction of points removed at random
    patches: int = 6  # spherical holes of 0.2-0.5 m radius
    outliers: float = 0.0005  # fraction of points added uniformly around the room


@dataclass
class RoomScan:
    """A generated room: its points and its ground truth."""

    points: np.ndarray  # (N, 6) x y z r g b
    polygon: np.ndarray  # (K, 2) true corners, clockwise seen from above
    floor_z: float
    ceiling_z: float
    shape: str


def room_polygon(shape: str, rng: np.random.Generator) -> np.ndarray:
    """A random clockwise floor polygon of the given shape with its corner at the origin."""
    width, depth = rng.uniform(4.0, 10.0), rng.uniform(4.0, 8.0)
    if shape == 'rect':
        ccw = [(0, 0), (width, 0), (width, depth), (0, depth)]
    elif shape == 'L':
        cut_w, cut_d = width * rng.uniform(0.3, 0.6), depth * rng.uniform(0.3, 0.6)
        ccw = [(0, 0), (width, 0), (width, depth - cut_d), (width - cut_w, depth - cut_d),
               (width - cut_w, depth), (0, depth)]
    elif shape == 'U':
        left, right = width * rng.uniform(0.25, 0.38), width * (1 - rng.uniform(0.25, 0.38))
        notch = depth * rng.uniform(0.3, 0.6)
        ccw = [(0, 0), (width, 0), (width, depth), (right, depth), (right, depth - notch),
               (left, depth - notch), (left, depth), (0, depth)]
    elif shape == 'T':
        stem_l, stem_r = width * rng.uniform(0.2, 0.35), width * (1 - rng.uniform(0.2, 0.35))
        bar = depth * rng.uniform(0.4, 0.6)
        ccw = [(stem_l, 0), (stem_r, 0), (stem_r, bar), (width, bar), (width, depth), (0, depth),
               (0, bar), (stem_l, bar)]
    elif shape == 'chamfer':  # a non-Manhattan wall cuts one corner at 30-60 degrees
        cut_w, cut_d = rng.uniform(1.0, 2.5), rng.uniform(1.0, 2.5)
        ccw = [(0, 0), (width, 0), (width, depth - cut_d), (width - cut_w, depth), (0, depth)]
    else:
        raise ValueError(f'unknown room shape {shape!r}, expected one of {SHAPES}')
    return np.array(ccw[::-1], dtype=np.float64)


def inside_polygon(xy: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Even-odd point-in-polygon test for (N, 2) points."""
    inside = np.zeros(len(xy), dtype=bool)
    for a, b in zip(polygon, np.roll(polygon, -1, axis=0)):
        crosses = (a[1] > xy[:, 1]) != (b[1] > xy[:, 1])
        with np.errstate(divide='ignore', invalid='ignore'):
            x_at = a[0] + (xy[:, 1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1])
        inside ^= crosses & (xy[:, 0] < x_at)
    return inside


def make_room(shape: str = 'rect',
              n_points: int = 300_000,
              seed: int = 0,
              noise: NoiseModel | None = None,
              furniture: int = 8,
              openings: bool = True,
              rotate: bool = True) -> RoomScan:
    """Generate a room scan of about ``n_points`` points with its true corners."""
    rng = np.random.default_rng(seed)
    polygon = room_polygon(shape, rng)
    height = rng.uniform(2.6, 3.6)
    perimeter = float(np.linalg.norm(np.roll(polygon, -1, 0) - polygon, axis=1).sum())
    floor_area = _area(polygon)
    density = n_points / (2 * floor_area + perimeter * height + 6.0 * furniture)

    parts = [
        sample_flat(polygon, 0.0, int(density * floor_area), rng, (150, 140, 130)),
        sample_flat(polygon, height, int(density * floor_area), rng, (230, 230, 225))
    ]
    walls = sample_walls(polygon, height, density, rng, openings)
    boxes = _place_furniture(polygon, furniture, rng)
    for box in boxes:
        parts.append(sample_box(box, density, rng))
        parts[0] = outside_box(parts[0], box, margin=0.0)
        walls = outside_box(walls, box, margin=0.15)  # a box against a wall hides it
    parts.append(walls)
    points = np.concatenate(parts)

    if noise is not None:
        points = _apply_noise(points, polygon, height, noise, rng)
    floor_z = rng.uniform(-1.0, 1.0)
    shift = rng.uniform(-20.0, 20.0, size=2)
    angle = rng.uniform(0, 2 * math.pi) if rotate else 0.0
    c, s = math.cos(angle), math.sin(angle)
    rotation = np.array([[c, -s], [s, c]])
    points[:, :2] = points[:, :2] @ rotation.T + shift
    points[:, 2] += floor_z
    polygon = polygon @ rotation.T + shift
    order = rng.permutation(len(points))
    return RoomScan(
        points=points[order],
        polygon=polygon,
        floor_z=floor_z,
        ceiling_z=floor_z + height,
        shape=shape)


def _area(polygon: np.ndarray) -> float:
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y)))


def _colored(xyz: np.ndarray, color: tuple[int, int, int], rng: np.random.Generator):
    rgb = np.clip(np.array(color) + rng.normal(0, 6, size=(len(xyz), 3)), 0, 255)
    return np.hstack([xyz, np.rint(rgb)])


def sample_flat(polygon, z, count, rng, color):
    """``count`` colored points spread uniformly over the polygon at height ``z``."""
    low, high = polygon.min(axis=0), polygon.max(axis=0)
    ratio = np.prod(high - low) / _area(polygon)
    xy = rng.uniform(low, high, size=(int(count * ratio * 1.05) + 10, 2))
    xy = xy[inside_polygon(xy, polygon)][:count]
    return _colored(np.column_stack([xy, np.full(len(xy), z)]), color, rng)


def sample_walls(polygon, height, density, rng, openings):
    """Points on the polygon's walls up to ``height``; ``openings``: a door and a window."""
    chunks = []
    edges = list(zip(polygon, np.roll(polygon, -1, axis=0)))
    lengths = [float(np.linalg.norm(b - a)) for a, b in edges]
    door_edge = int(rng.integers(len(edges))) if openings else -1
    window_edge = int(rng.integers(len(edges))) if openings else -1
    for index, ((a, b), length) in enumerate(zip(edges, lengths)):
        count = int(density * length * height)
        t = rng.uniform(0, length, count)
        z = rng.uniform(0, height, count)
        keep = np.ones(count, dtype=bool)
        if index == door_edge and length > 1.6:
            start = rng.uniform(0.3, length - 1.2)
            keep &= ~((t > start) & (t < start + 0.9) & (z < 2.1))
        if index == window_edge and length > 2.0:
            start = rng.uniform(0.4, length - 1.6)
            keep &= ~((t > start) & (t < start + 1.2) & (z > 0.9) & (z < 2.1))
        direction = (b - a) / length
        xy = a + t[keep, None] * direction
        chunks.append(_colored(np.column_stack([xy, z[keep]]), (210, 205, 195), rng))
    return np.concatenate(chunks)


def _place_furniture(polygon, count, rng):
    """Boxes (centre xy, size xyz, yaw, against_wall): tables and chairs free, cabinets
    against walls."""
    boxes = []
    edges = list(zip(polygon, np.roll(polygon, -1, axis=0)))
    attempts = 0
    while len(boxes) < count and attempts < 50 * count:
        attempts += 1
        if rng.random() < 0.35:  # cabinet or bookcase against a wall
            a, b = edges[int(rng.integers(len(edges)))]
            length = float(np.linalg.norm(b - a))
            size = np.array([rng.uniform(0.6, 1.6), rng.uniform(0.35, 0.6), rng.uniform(0.8, 2.2)])
            if length < size[0] + 0.4:
                continue
            direction = (b - a) / length
            inward = np.array([direction[1], -direction[0]])  # right side of a clockwise edge
            centre = a + direction * rng.uniform(0.2 + size[0] / 2, length - 0.2 - size[0] / 2) \
                + inward * (size[1] / 2 + 0.01)
            yaw = math.atan2(direction[1], direction[0])  # local +y points at the wall
            against_wall = True
        else:  # table or chair somewhere in the room
            size = np.array([rng.uniform(0.4, 1.8), rng.uniform(0.4, 1.0), rng.uniform(0.45, 1.1)])
            centre = rng.uniform(polygon.min(axis=0), polygon.max(axis=0))
            yaw = rng.uniform(0, math.pi)
            against_wall = False
        footprint = _box_corners(centre, size, yaw)
        grown = _box_corners(centre, size + 0.1, yaw)
        if inside_polygon(np.vstack([footprint, centre]), polygon).all() and \
                not inside_polygon(polygon, grown).any():  # no reflex corner inside the box
            boxes.append((centre, size, yaw, against_wall))
    return boxes


def _box_corners(centre, size, yaw):
    c, s = math.cos(yaw), math.sin(yaw)
    local = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * size[:2] / 2
    return local @ np.array([[c, s], [-s, c]]) + centre


def sample_box(box, density, rng):
    """Points on the top and sides of a box; the back of a box against a wall is hidden."""
    centre, size, yaw, against_wall = box
    faces = [(size[0] * size[1], 'top'), (size[0] * size[2], 'x'), (size[0] * size[2], 'x'),
             (size[1] * size[2], 'y'), (size[1] * size[2], 'y')]
    chunks = []
    for sign_index, (area, kind) in enumerate(faces):
        if against_wall and sign_index == 1:
            continue
        count = int(density * area)
        u = rng.uniform(-0.5, 0.5, (count, 3)) * size
        if kind == 'top':
            u[:, 2] = size[2] / 2
        elif kind == 'x':
            u[:, 1] = (1 if sign_index % 2 else -1) * size[1] / 2
        else:
            u[:, 0] = (1 if sign_index % 2 else -1) * size[0] / 2
        c, s = math.cos(yaw), math.sin(yaw)
        xy = u[:, :2] @ np.array([[c, s], [-s, c]]) + centre
        chunks.append(np.column_stack([xy, u[:, 2] + size[2] / 2]))
    color = tuple(int(v) for v in rng.integers(40, 200, 3))
    return _colored(np.concatenate(chunks), color, rng)


def outside_box(points, box, margin):
    """Drop points inside the box's footprint (grown by margin) below its top."""
    centre, size, yaw, _ = box
    c, s = math.cos(yaw), math.sin(yaw)
    local = (points[:, :2] - centre) @ np.array([[c, -s], [s, c]])
    inside = (np.abs(local[:, 0]) < size[0] / 2) & (np.abs(local[:, 1]) < size[1] / 2 + margin) \
        & (points[:, 2] < size[2])
    return points[~inside]


def _apply_noise(points, polygon, height, noise, rng):
    scanner = _scanner_position(polygon, height, rng)
    rays = points[:, :3] - scanner
    distance = np.linalg.norm(rays, axis=1, keepdims=True)
    unit = rays / np.maximum(distance, 1e-9)
    helper = np.where(np.abs(unit[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    across_1 = np.cross(unit, helper)
    across_1 /= np.linalg.norm(across_1, axis=1, keepdims=True)
    across_2 = np.cross(unit, across_1)
    jitter = rng.normal(0, noise.angular_sigma, size=(len(points), 2)) * distance
    moved = points.copy()
    moved[:, :3] += unit * rng.normal(0, noise.range_sigma, size=(len(points), 1)) \
        + across_1 * jitter[:, :1] + across_2 * jitter[:, 1:]
    keep = rng.random(len(moved)) >= noise.dropout
    for _ in range(noise.patches):
        centre = moved[int(rng.integers(len(moved))), :3]
        keep &= np.linalg.norm(moved[:, :3] - centre, axis=1) > rng.uniform(0.2, 0.5)
    moved = moved[keep]
    count = int(noise.outliers * len(moved))
    low = np.append(polygon.min(axis=0) - 0.5, -0.2)
    high = np.append(polygon.max(axis=0) + 0.5, height + 0.2)
    outliers = _colored(rng.uniform(low, high, size=(count, 3)), (128, 128, 128), rng)
    return np.concatenate([moved, outliers])


def _scanner_position(polygon, height, rng):
    low, high = polygon.min(axis=0), polygon.max(axis=0)
    while True:
        xy = rng.uniform(low, high, size=(1, 2))
        if inside_polygon(xy, polygon)[0]:
            return np.array([xy[0, 0], xy[0, 1], min(1.5, height - 0.3)])
