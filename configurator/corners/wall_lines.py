"""Wall lines refitted to the wall points near each outline edge, and their corners."""
from __future__ import annotations
import math
from dataclasses import dataclass

import numpy as np

from configurator.corners.params import CornerParams
from configurator.corners.simplify import line_intersection


@dataclass
class WallLine:
    """A wall line fitted to an outline edge (wall-aligned frame) and how well points back it."""

    point: np.ndarray  # a point on the line
    direction: np.ndarray  # unit vector along the polygon's clockwise traversal
    inliers: int = 0
    support: float = 0.0  # fraction of the edge length backed by inlier points


def fit_wall_lines(outline: np.ndarray, walls: np.ndarray, band: float,
                   params: CornerParams) -> list[WallLine]:
    """Refit every outline edge to the wall points within ``band`` of it (wall frame)."""
    index = _BucketIndex(walls, bucket=0.5)
    lines = []
    for i in range(len(outline)):
        a, b = outline[i], outline[(i + 1) % len(outline)]
        length = float(np.linalg.norm(b - a))
        direction = (b - a) / length
        normal = np.array([-direction[1], direction[0]])  # outward for clockwise polygons
        margin = min(0.2, 0.3 * length)
        near = index.in_box(np.minimum(a, b) - band, np.maximum(a, b) + band)
        offset = (near - a) @ normal
        along = (near - a) @ direction
        near = near[(np.abs(offset) < band) & (along > margin) & (along < length - margin)]
        line = WallLine(point=a.copy(), direction=direction)
        if len(near) >= 10:
            offset = (near - a) @ normal
            bins = np.arange(-band, band + 0.005, 0.005)
            hist = np.convolve(np.histogram(offset, bins)[0], np.ones(5), mode='same')
            peak = bins[int(np.argmax(hist))] + 0.0025
            inliers = near[np.abs(offset - peak) < params.inlier_width]
            for _ in range(2):  # total least squares, then refit on the fitted line's slab
                if len(inliers) < 10:
                    break
                centre = inliers.mean(axis=0)
                _, vectors = np.linalg.eigh(np.cov((inliers - centre).T))
                fitted = vectors[:, 1] * np.sign(vectors[:, 1] @ direction)
                line = WallLine(point=centre, direction=fitted, inliers=len(inliers))
                residual = (near - centre) @ np.array([-fitted[1], fitted[0]])
                inliers = near[np.abs(residual) < params.inlier_width]
            if line.inliers:
                usable = max(length - 2 * margin, 1e-6)
                along = (inliers - a) @ direction
                covered = np.unique(np.floor((along - margin) / 0.1).astype(int))
                line.support = float(min(1.0, len(covered) * 0.1 / usable))
        lines.append(line)
    return lines


def drop_wall_less_bumps(lines: list[WallLine], params: CornerParams) -> list[WallLine]:
    """Drop runs of edges without wall points that bulge out of one straight wall.

    Such a bump is floor or clutter seen through a door. It is recognised by its neighbours,
    which are the two halves of one wall (parallel and within 10 cm). An unsupported run
    between different walls, such as a sparsely scanned arm, is kept.
    """
    weak = [line.support < params.min_line_support for line in lines]
    if all(weak) or not any(weak):
        return lines
    count = len(lines)
    drop = np.zeros(count, dtype=bool)
    start = next(i for i in range(count) if not weak[i])  # begin the walk at a supported line
    i = start
    for _ in range(count):
        j = (i + 1) % count
        if not weak[i] and weak[j]:
            end = j
            while weak[end]:
                end = (end + 1) % count
            before, after = lines[i], lines[end]
            sine = abs(before.direction[0] * after.direction[1] -
                       before.direction[1] * after.direction[0])
            normal = np.array([-before.direction[1], before.direction[0]])
            offset = abs(float((after.point - before.point) @ normal))
            if sine < math.sin(params.min_turn) and offset < 0.1 and \
                    before.direction @ after.direction > 0:
                k = j
                while k != end:
                    drop[k] = True
                    k = (k + 1) % count
        i = j
    return [line for line, dropped in zip(lines, drop) if not dropped]


class _BucketIndex:
    """2D points sorted into square buckets, for fast bounding-box queries."""

    def __init__(self, points: np.ndarray, bucket: float):
        self.bucket = bucket
        self.origin = points.min(axis=0)
        keys = np.floor((points - self.origin) / bucket).astype(np.int64)
        self.rows = int(keys[:, 1].max()) + 1
        linear = keys[:, 0] * self.rows + keys[:, 1]
        order = np.argsort(linear, kind='stable')
        self.keys = linear[order]
        self.points = points[order]
        self.columns = int(keys[:, 0].max()) + 1

    def in_box(self, low: np.ndarray, high: np.ndarray) -> np.ndarray:
        """The points inside the axis-aligned box [low, high]."""
        first = np.maximum(np.floor((low - self.origin) / self.bucket).astype(int), 0)
        last = np.floor((high - self.origin) / self.bucket).astype(int)
        last = np.minimum(last, [self.columns - 1, self.rows - 1])
        chunks = []
        for column in range(first[0], last[0] + 1):
            start = np.searchsorted(self.keys, column * self.rows + first[1])
            stop = np.searchsorted(self.keys, column * self.rows + last[1], side='right')
            chunks.append(self.points[start:stop])
        if not chunks:
            return np.zeros((0, 2))
        near = np.concatenate(chunks)
        return near[((near >= low) & (near <= high)).all(axis=1)]


def snap_directions(lines: list[WallLine], snap_angle: float) -> list[WallLine]:
    """Snap lines near the frame's axes to one common, refined Manhattan direction."""
    quarter = math.pi / 2
    deviations, weights = [], []
    for line in lines:
        theta = math.atan2(line.direction[1], line.direction[0])
        deviation = (theta + quarter / 2) % quarter - quarter / 2
        deviations.append(deviation)
        weights.append(line.inliers if abs(deviation) < snap_angle else 0)
    if sum(weights) == 0:
        return lines
    common = float(np.average(deviations, weights=weights))
    snapped = []
    for line, deviation in zip(lines, deviations):
        if abs(deviation) < snap_angle or line.inliers == 0:
            theta = math.atan2(line.direction[1], line.direction[0]) - deviation + common
            line = WallLine(
                point=line.point,
                direction=np.array([math.cos(theta), math.sin(theta)]),
                inliers=line.inliers,
                support=line.support)
        snapped.append(line)
    return snapped


def intersect_lines(lines: list[WallLine], min_edge: float, min_turn: float) -> np.ndarray:
    """Corners between consecutive wall lines; degenerate walls are dropped and retried."""
    lines = list(lines)
    while len(lines) >= 3:
        n = len(lines)
        corners = []
        parallel = None
        for i in range(n):
            previous, current = lines[i - 1], lines[i]
            point = line_intersection(
                previous.point,
                previous.direction,
                current.point,
                current.direction,
                min_sine=math.sin(min_turn))
            if point is None:
                parallel = i
                break
            corners.append(point)
        if parallel is not None:  # two consecutive (anti)parallel walls: keep the better one
            weaker = min((parallel - 1) % n, parallel, key=lambda j: lines[j].inliers)
            del lines[weaker]
            continue
        corners = np.array(corners)
        lengths = np.linalg.norm(np.roll(corners, -1, axis=0) - corners, axis=1)
        edge_dirs = np.roll(corners, -1, axis=0) - corners
        agrees = np.einsum('ij,ij->i', edge_dirs, [line.direction for line in lines]) > 0
        bad = np.flatnonzero((lengths < min_edge / 2) | ~agrees)
        if len(bad) == 0:
            return corners
        del lines[int(min(bad, key=lambda j: lines[j].inliers))]
    return np.zeros((0, 2))
