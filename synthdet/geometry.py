"""2D geometry of floor polygons and boxes: metres, x/y seen from above, yaw counter-clockwise.

The exact predicates (``signed_area``, ``segments_touch``, ``first_self_crossing``) are plain
Python on any sequence of ``(x, y)`` pairs, because ``synthdet.contracts`` uses them inside
FreeCAD's own Python with the standard library alone; numpy is therefore imported by the
vectorised helpers that need it, not by this module.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

if TYPE_CHECKING:
    import numpy as np

EPS = 1e-12


def _pairs(polygon) -> list:
    """``polygon`` as a list of ``[x, y]`` (numpy arrays are converted in one call)."""
    return polygon.tolist() if hasattr(polygon, 'tolist') else list(polygon)


def signed_area(polygon) -> float:
    """Shoelace area of a closed polygon: positive counter-clockwise, negative clockwise.
    Taken around the first corner, so coordinates far from the origin (a georeferenced room
    at 1e15 m) do not drown the area in rounding."""
    points = _pairs(polygon)
    if not points:
        return 0.0
    ox, oy = points[0]
    total = 0.0
    for (x0, y0), (x1, y1) in zip(points, points[1:] + points[:1]):
        total += (x0 - ox) * (y1 - oy) - (x1 - ox) * (y0 - oy)
    return total / 2.0


def segments_touch(p, q, r, s, eps: float = EPS) -> bool:
    """Whether the closed segments ``pq`` and ``rs`` cross or touch."""

    def orientation(a, b, c) -> int:
        value = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
        return (value > eps) - (value < -eps)

    def on_segment(a, b, c) -> bool:  # c on the segment ab, given collinear
        return (min(a[0], b[0]) - eps <= c[0] <= max(a[0], b[0]) + eps
                and min(a[1], b[1]) - eps <= c[1] <= max(a[1], b[1]) + eps)

    o1, o2, o3, o4 = orientation(p, q, r), orientation(p, q, s), orientation(r, s, p), \
        orientation(r, s, q)
    if o1 != o2 and o3 != o4:
        return True
    return ((o1 == 0 and on_segment(p, q, r)) or (o2 == 0 and on_segment(p, q, s))
            or (o3 == 0 and on_segment(r, s, p)) or (o4 == 0 and on_segment(r, s, q)))


def first_self_crossing(polygon) -> tuple[int, int] | None:
    """The first pair ``(i, j)``, ``i < j``, of non-adjacent edges (edge i runs from corner i
    to i+1) of a closed polygon that cross or touch, or None for a simple polygon.

    A sweep along x: only edges whose x and y extents overlap are tested, so a room outline of
    a thousand corners costs about as many tests as it has edges, not half a million pairs."""
    points = _pairs(polygon)
    count = len(points)
    edges = [(points[i], points[(i + 1) % count]) for i in range(count)]
    active: list[tuple[float, int]] = []  # (right end, edge) of the edges the sweep is inside
    found = None
    for i in sorted(range(count), key=lambda k: min(edges[k][0][0], edges[k][1][0])):
        (px, py), (qx, qy) = edges[i]
        active = [(right, j) for right, j in active if right >= min(px, qx) - EPS]
        for _, j in active:
            first, second = min(i, j), max(i, j)
            if second == first + 1 or (first == 0 and second == count - 1):
                continue  # adjacent edges share a corner
            (rx, ry), (sx, sy) = edges[j]
            if max(ry, sy) < min(py, qy) - EPS or min(ry, sy) > max(py, qy) + EPS:
                continue
            if (found is None or (first, second) < found) and segments_touch(
                    edges[first][0], edges[first][1], edges[second][0], edges[second][1]):
                found = (first, second)
        active.append((max(px, qx), i))
    return found


def clockwise(polygon) -> np.ndarray:
    """The polygon as a float ``(N, 2)`` array, reversed if it runs counter-clockwise."""
    import numpy as np
    polygon = np.asarray(polygon, dtype=np.float64)
    return polygon[::-1].copy() if signed_area(polygon) > 0 else polygon


def rotation2d(yaw: float) -> np.ndarray:
    """The 2x2 matrix turning vectors counter-clockwise by ``yaw`` radians."""
    import numpy as np
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s], [s, c]])


def box_corners_xy(center: Sequence[float], size: Sequence[float], yaw: float) -> np.ndarray:
    """Floor footprint (4, 2) of an oriented box, counter-clockwise; ``size`` is along the box's
    own axes and ``yaw`` turns it counter-clockwise about ``center``."""
    import numpy as np
    hx, hy = size[0] / 2, size[1] / 2
    local = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
    return local @ rotation2d(yaw).T + np.asarray(center[:2], dtype=float)


def points_in_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Even-odd test of 2D points (M, 2) in a simple polygon (N, 2); the boundary counts as
    either side. Memory grows with M, not M x N."""
    import numpy as np
    points, polygon = np.asarray(points, dtype=float), np.asarray(polygon, dtype=float)
    x, y = points[:, 0], points[:, 1]
    inside = np.zeros(len(points), dtype=bool)
    for (x0, y0), (x1, y1) in zip(polygon, np.roll(polygon, -1, axis=0)):
        crosses = (y0 > y) != (y1 > y)
        if crosses.any():
            x_at = x0 + (y[crosses] - y0) * (x1 - x0) / (y1 - y0)
            inside[crosses] ^= x[crosses] < x_at
    return inside


def distance_to_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Distance from each 2D point (M, 2) to the boundary of the closed polygon (N, 2)."""
    import numpy as np
    points, polygon = np.asarray(points, dtype=float), np.asarray(polygon, dtype=float)
    best = np.full(len(points), np.inf)
    for a, b in zip(polygon, np.roll(polygon, -1, axis=0)):
        d = b - a
        t = np.clip(((points - a) @ d) / max(float(d @ d), 1e-12), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(points - (a + t[:, None] * d), axis=1))
    return best


def edges_cross(a: np.ndarray, b: np.ndarray, eps: float = 1e-9) -> bool:
    """True if an edge of closed polygon ``a`` properly crosses an edge of ``b`` (touching and
    collinear overlaps do not count)."""
    import numpy as np
    p0, p1 = a[:, None, :], np.roll(a, -1, axis=0)[:, None, :]
    q0, q1 = b[None, :, :], np.roll(b, -1, axis=0)[None, :, :]

    def orient(u, v, w):
        return (v[..., 0] - u[..., 0]) * (w[..., 1] - u[..., 1]) - (v[..., 1] - u[..., 1]) * (
            w[..., 0] - u[..., 0])

    d1, d2 = orient(q0, q1, p0), orient(q0, q1, p1)
    d3, d4 = orient(p0, p1, q0), orient(p0, p1, q1)
    return bool(np.any((d1 * d2 < -eps) & (d3 * d4 < -eps)))


def grid_cells(polygon: np.ndarray) -> list[np.ndarray]:
    """Rectangles (4, 2), clockwise from (x0, y0), of the grid through an axis-aligned polygon's
    corner coordinates whose centres lie inside it: a box room has one, an L room three, a U or
    T room five."""
    import numpy as np
    polygon = np.asarray(polygon, dtype=float)
    xs, ys = np.unique(polygon[:, 0]), np.unique(polygon[:, 1])
    cells = []
    for x0, x1 in zip(xs[:-1], xs[1:]):
        for y0, y1 in zip(ys[:-1], ys[1:]):
            if points_in_polygon(np.array([[(x0 + x1) / 2, (y0 + y1) / 2]]), polygon)[0]:
                cells.append(np.array([[x0, y0], [x0, y1], [x1, y1], [x1, y0]]))
    return cells


def rotation_z(yaw: float) -> np.ndarray:
    """The 3x3 matrix turning vectors counter-clockwise about z by ``yaw`` radians."""
    import numpy as np
    rotation = np.eye(3)
    rotation[:2, :2] = rotation2d(yaw)
    return rotation


def rotation_between(a: Sequence[float], b: Sequence[float]) -> np.ndarray:
    """The 3x3 rotation turning the direction ``a`` onto ``b`` by the smallest angle (about
    their common normal; a half turn about a perpendicular axis when they are opposite)."""
    import numpy as np
    a = np.asarray(a, dtype=np.float64) / np.linalg.norm(a)
    b = np.asarray(b, dtype=np.float64) / np.linalg.norm(b)
    axis = np.cross(a, b)
    sine, cosine = float(np.linalg.norm(axis)), float(a @ b)
    if sine < 1e-12:
        if cosine > 0:
            return np.eye(3)
        helper = np.eye(3)[int(np.argmin(np.abs(a)))]
        axis = np.cross(a, helper) / np.linalg.norm(np.cross(a, helper))
        return 2.0 * np.outer(axis, axis) - np.eye(3)  # half turn about axis
    axis /= sine
    cross = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + sine * cross + (1 - cosine) * cross @ cross


def projection_sharpness(values: np.ndarray, weights: np.ndarray | None, cell: float) -> float:
    """Sum of squared ``weights`` (default 1) per ``cell``-wide bin of 1D ``values``: large
    when the values pile up on a few levels (planes seen edge-on). Bins are counted over
    their range when it is small, else by sorting, so far stray values cost no memory."""
    import numpy as np
    bins = np.floor(values / cell).astype(np.int64)
    low, high = (int(bins.min()), int(bins.max())) if len(bins) else (0, 0)
    if high - low <= 4 * len(bins) + 1024:
        counts = np.bincount(bins - low, weights)
    else:
        _, inverse = np.unique(bins, return_inverse=True)
        counts = np.bincount(inverse.ravel(), weights)
    return float(np.square(counts).sum())


def dominant_direction(xy: np.ndarray, cell: float = 0.02) -> float:
    """Direction in [0, pi/2) of the dominant (Manhattan) walls of 2D wall points.

    The points are pooled into occupied ``cell`` squares (a hash of the cells, so memory
    follows the points, not their bounding box); for each candidate angle the cells are
    projected onto the two rotated axes and the angle with the sharpest projections wins: a
    1 degree sweep, then a 0.05 degree refinement.
    """
    import numpy as np
    xy = np.asarray(xy, dtype=np.float64)
    cells, counts = np.unique(np.floor(xy / cell).astype(np.int64), axis=0, return_counts=True)
    centres = (cells - cells[len(cells) // 2]) * cell
    weights = counts.astype(np.float64)

    def sharpness(theta: float) -> float:
        c, s = np.cos(theta), np.sin(theta)
        return projection_sharpness(centres @ [c, s], weights, cell) + \
            projection_sharpness(centres @ [-s, c], weights, cell)

    coarse = np.radians(np.arange(0.0, 90.0, 1.0))
    best = coarse[int(np.argmax([sharpness(t) for t in coarse]))]
    fine = best + np.radians(np.arange(-1.0, 1.0001, 0.05))
    best = fine[int(np.argmax([sharpness(t) for t in fine]))]
    return float(best % (np.pi / 2))
