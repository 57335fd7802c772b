"""The outline of a set of grid cells as a lattice polygon (crack following): the room's
footprint (:mod:`configurator.corners`) and the cells of the walls-first outline
(:mod:`configurator.wall_evidence`) are traced with it."""
from __future__ import annotations

import numpy as np

from synthdet.geometry import signed_area


def trace_boundary(mask: np.ndarray) -> np.ndarray:
    """Outer boundary of a 2D boolean mask (``mask[ix, iy]``) as a clockwise lattice polygon.

    Crack following: every side between an inside and an outside cell becomes a directed
    edge with the inside on its right; edges are chained (turning right at the rare
    diagonal contacts) and the loop enclosing the largest area is returned as ``(K, 2)``
    lattice coordinates (cell corners) with collinear vertices removed.
    """
    padded = np.pad(mask.astype(bool), 1)
    inside = padded[1:-1, 1:-1]
    ix, iy = np.nonzero(inside & ~padded[1:-1, :-2])  # bottom side open
    starts = [np.stack([ix + 1, iy], 1)]
    ends = [np.stack([ix, iy], 1)]
    ix, iy = np.nonzero(inside & ~padded[1:-1, 2:])  # top side open
    starts.append(np.stack([ix, iy + 1], 1))
    ends.append(np.stack([ix + 1, iy + 1], 1))
    ix, iy = np.nonzero(inside & ~padded[:-2, 1:-1])  # left side open
    starts.append(np.stack([ix, iy], 1))
    ends.append(np.stack([ix, iy + 1], 1))
    ix, iy = np.nonzero(inside & ~padded[2:, 1:-1])  # right side open
    starts.append(np.stack([ix + 1, iy + 1], 1))
    ends.append(np.stack([ix + 1, iy], 1))
    starts = np.concatenate(starts)
    ends = np.concatenate(ends)
    if len(starts) == 0:
        return np.zeros((0, 2))

    outgoing: dict[tuple[int, int], list[int]] = {}
    for index, start in enumerate(map(tuple, starts.tolist())):
        outgoing.setdefault(start, []).append(index)
    used = np.zeros(len(starts), dtype=bool)
    best_loop, best_area = None, 0.0
    for first in range(len(starts)):
        if used[first]:
            continue
        loop = []
        edge = first
        while not used[edge]:
            used[edge] = True
            loop.append(starts[edge])
            here = tuple(ends[edge].tolist())
            heading = ends[edge] - starts[edge]
            options = [e for e in outgoing[here] if not used[e]]
            if not options:
                break
            # prefer the right turn, then straight on, then left (keeps diagonal contacts apart)
            edge = min(options, key=lambda e: _turn_rank(heading, ends[e] - starts[e]))
        polygon = np.array(loop, dtype=np.float64)
        area = -signed_area(polygon)  # clockwise loops have negative signed area
        if area > best_area:
            best_loop, best_area = polygon, area
    if best_loop is None:
        return np.zeros((0, 2))
    return _drop_collinear(best_loop)


def _turn_rank(heading: np.ndarray, new: np.ndarray) -> int:
    """0 for a right turn from ``heading`` to ``new``, 1 straight on, 2 left."""
    cross = heading[0] * new[1] - heading[1] * new[0]
    return 0 if cross < 0 else (1 if cross == 0 else 2)


def _drop_collinear(polygon: np.ndarray) -> np.ndarray:
    """The polygon without its vertices on a straight line."""
    previous = np.roll(polygon, 1, axis=0)
    following = np.roll(polygon, -1, axis=0)
    a = polygon - previous
    b = following - polygon
    cross = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return polygon[np.abs(cross) > 1e-9]
