"""Simplification of a closed room polygon: Douglas-Peucker, small turns and short walls."""
from __future__ import annotations

import numpy as np


def simplify_outline(polygon: np.ndarray, tolerance: float, min_edge: float,
                     min_turn: float) -> np.ndarray:
    """Simplify a closed clockwise polygon: Douglas-Peucker, then merge short walls.

    A wall shorter than ``min_edge`` disappears: if its neighbours are (anti)parallel (a
    jog or a spike) both its ends are dropped, otherwise its ends are replaced by the
    intersection of the neighbouring walls. Vertices turning less than ``min_turn`` go.
    """
    polygon = _douglas_peucker_closed(np.asarray(polygon, dtype=np.float64), tolerance)
    while len(polygon) >= 3:
        polygon = _drop_small_turns(polygon, min_turn)
        if len(polygon) < 3:
            break
        lengths = np.linalg.norm(np.roll(polygon, -1, axis=0) - polygon, axis=1)
        shortest = int(np.argmin(lengths))
        if lengths[shortest] >= min_edge:
            break
        polygon = _remove_edge(polygon, shortest)
    return polygon


def _douglas_peucker_closed(polygon: np.ndarray, tolerance: float) -> np.ndarray:
    if len(polygon) <= 3:
        return polygon
    first = 0
    far = int(np.argmax(np.linalg.norm(polygon - polygon[first], axis=1)))
    keep = np.zeros(len(polygon), dtype=bool)
    keep[[first, far]] = True
    closed = np.vstack([polygon, polygon[:1]])
    for start, end in ((first, far), (far, len(polygon))):
        stack = [(start, end)]
        while stack:
            i, j = stack.pop()
            if j - i < 2:
                continue
            a, b = closed[i], closed[j]
            segment = closed[i + 1:j]
            direction = b - a
            norm = np.linalg.norm(direction)
            if norm < 1e-12:
                distance = np.linalg.norm(segment - a, axis=1)
            else:
                distance = np.abs(direction[0] * (segment[:, 1] - a[1]) - direction[1] *
                                  (segment[:, 0] - a[0])) / norm
            k = int(np.argmax(distance))
            if distance[k] > tolerance:
                keep[i + 1 + k] = True
                stack += [(i, i + 1 + k), (i + 1 + k, j)]
    return polygon[keep]


def _drop_small_turns(polygon: np.ndarray, min_turn: float) -> np.ndarray:
    while len(polygon) >= 3:
        incoming = polygon - np.roll(polygon, 1, axis=0)
        outgoing = np.roll(polygon, -1, axis=0) - polygon
        turn = np.abs(
            np.arctan2(incoming[:, 0] * outgoing[:, 1] - incoming[:, 1] * outgoing[:, 0],
                       (incoming * outgoing).sum(axis=1)))
        weakest = int(np.argmin(turn))
        if turn[weakest] >= min_turn:
            break
        polygon = np.delete(polygon, weakest, axis=0)
    return polygon


def _remove_edge(polygon: np.ndarray, k: int) -> np.ndarray:
    """Remove edge k (from vertex k to k+1) of a closed polygon."""
    n = len(polygon)
    before, start, end, after = (polygon[(k + i) % n] for i in (-1, 0, 1, 2))
    crossing = line_intersection(before, start - before, end, after - end, min_sine=0.5)
    kept = [i for i in range(n) if i not in (k, (k + 1) % n)]
    if crossing is None or n <= 4:
        return polygon[kept]
    result = polygon.copy()
    result[k] = crossing
    return np.delete(result, (k + 1) % n, axis=0)


def line_intersection(p: np.ndarray, d: np.ndarray, q: np.ndarray, e: np.ndarray,
                      min_sine: float) -> np.ndarray | None:
    """Intersection of lines p + s d and q + t e, or None if they are nearly parallel."""
    cross = d[0] * e[1] - d[1] * e[0]
    if abs(cross) <= min_sine * np.linalg.norm(d) * np.linalg.norm(e):
        return None
    s = ((q[0] - p[0]) * e[1] - (q[1] - p[1]) * e[0]) / cross
    return p + s * d


def edge_length(polygon: np.ndarray, i: int) -> float:
    """Length of edge ``i`` (from vertex ``i`` to the next) of a closed polygon."""
    return float(np.linalg.norm(polygon[(i + 1) % len(polygon)] - polygon[i]))
