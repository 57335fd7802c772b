"""Room outlines built on the walls a scan shows, where its footprint's outline is not a room.

A reconstruction with holes, a room seen through its doors or one depth view of one side of a
room has a footprint whose outline follows occlusions, not walls: the wall points back too
little of it for :func:`configurator.corners.detect_corners` to fit its edges. Here the walls
come first (``docs/corners.md``, "Walls first"):

1. **Wall planes.** In the wall-aligned frame, the wall points' x and y coordinates are
   histogrammed (1 cm bins); each peak holding enough points is a wall plane at the median
   of its points, with the intervals along it that its points cover (gaps under
   ``plane_gap`` bridged).
2. **Cells.** The wall planes, and the footprint's extent, cut the plan into rectangular
   cells; each cell knows the share of its area the (closed, hole-filled) footprint covers.
3. **Labels.** A minimum cut labels every cell inside or outside the room: leaving out a
   covered area, and taking in an uncovered one, cost their areas; a boundary costs
   ``boundary_weight`` per metre that no wall point backs. So the room's edges lie on wall
   planes where there are walls, a pocket or notch that no wall backs is filled, and the sides
   the scan never saw close along the footprint's extent.
4. **Outline.** The boundary of the biggest inside region, traced along the cell edges and
   simplified, with the share of each edge that wall points back.
"""
from __future__ import annotations
import math
from dataclasses import dataclass, replace
import numpy as np
from scipy import ndimage
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import breadth_first_order, maximum_flow
from scipy.spatial import ConvexHull

from configurator.corners.levels import Levels, wall_points
from configurator.corners.params import CornerDetectionError, CornerParams
from configurator.lattice_outline import trace_boundary
from synthdet.geometry import points_in_polygon, signed_area


@dataclass(frozen=True)
class WallEvidenceParams:
    """Tuning of :func:`walled_outline`; lengths in metres."""

    plane_bin: float = 0.01  # histogram bin of the wall-plane search
    plane_width: float = 0.03  # half width of the slab of points that belong to a plane
    min_plane_length: float = 0.6  # a plane backs at least this much wall
    min_points_per_metre: float = 20.0  # ... with this many wall points per metre
    min_prominence: float = 3.0  # ... and this many times the points 0.15-0.5 m off it
    plane_step: float = 0.1  # a plane's extent is measured in steps of this length
    plane_gap: float = 0.3  # gaps along a plane up to this long are bridged (clutter, doors)
    min_plane_spacing: float = 0.15  # a weaker plane closer than this to a stronger one goes
    evidence_reach: float = 1.0  # wall evidence: columns reaching this high above the floor
    footprint_cell: float = 0.05  # the finest footprint cell; coarser for sparse scans
    points_per_cell: float = 4.0  # ... which hold about this many points each
    boundary_weight: float = 0.3  # cost of a metre of boundary without wall, in m^2 of area
    unseen_weight: float = 0.1  # cost of taking in a square metre the points do not cover
    min_pocket_backing: float = 0.5  # an outside pocket walls back less than this is filled
    min_seen_area: float = 0.5  # the points span at least this share of the outline's area
    min_held: float = 0.5  # ... and the outline holds at least this share of their footprint


@dataclass
class WallPlane:
    """A vertical wall plane of the wall-aligned frame: ``axis`` 0 is the line x = offset,
    1 the line y = offset; ``intervals`` are the stretches along it that wall points back."""

    axis: int
    offset: float
    intervals: np.ndarray  # (K, 2) start and end along the other axis

    @property
    def length(self) -> float:
        """The length of wall the plane's points back."""
        return float((self.intervals[:, 1] - self.intervals[:, 0]).sum())


@dataclass
class WalledOutline:
    """Result of :func:`walled_outline`, in the wall-aligned frame."""

    corners: np.ndarray  # (K, 2) clockwise
    supports: np.ndarray  # (K,) share of edge k (corner k to k + 1) that wall points back
    seen: float  # share of the perimeter that wall points back
    seen_area: float  # share of the outline's area that the points' footprint spans
    held: float  # share of the footprint's area inside the outline


def walled_outline(frame_xy: np.ndarray, frame_walls: np.ndarray,
                   params: CornerParams,
                   tuning: WallEvidenceParams | None = None) -> WalledOutline | None:
    """The room outline of plan points ``frame_xy`` built on the planes of their wall points
    ``frame_walls`` (both in the wall-aligned frame); None when the scan shows no wall plane
    or the outline has no area."""
    tuning = tuning or WallEvidenceParams()
    planes = [plane for axis in (0, 1) for plane in wall_planes(frame_walls, axis, tuning)]
    if not planes:
        return None
    extent = np.ptp(frame_xy, axis=0)
    cell = float(np.clip(math.sqrt(tuning.points_per_cell * extent[0] * extent[1] /
                                   len(frame_xy)), tuning.footprint_cell, 0.2))
    footprint = Footprint(frame_xy, cell)
    low, high = footprint.extent()
    cuts = [_cut_positions(planes, axis, low[axis], high[axis], params.min_edge)
            for axis in (0, 1)]
    inside = _label_cells(cuts, planes, footprint, tuning)
    if not inside.any():
        return None
    lattice = trace_boundary(inside).astype(int)  # edges of at least min_edge, as the cuts
    corners = np.column_stack([cuts[0][lattice[:, 0]], cuts[1][lattice[:, 1]]])
    if len(corners) < 3 or signed_area(corners) >= 0:
        return None
    supports = np.array([_edge_support(corners[k], corners[(k + 1) % len(corners)], planes,
                                       tuning.plane_width) for k in range(len(corners))])
    lengths = np.linalg.norm(np.roll(corners, -1, axis=0) - corners, axis=1)
    return WalledOutline(corners=corners, supports=supports,
                         seen=float((supports * lengths).sum() / lengths.sum()),
                         seen_area=footprint.spanned_share(corners),
                         held=footprint.held_share(corners))


def wall_planes(frame_walls: np.ndarray, axis: int,
                tuning: WallEvidenceParams | None = None) -> list[WallPlane]:
    """The wall planes across ``axis`` (lines where that coordinate is constant) of wall
    points given in the wall-aligned frame, strongest first."""
    tuning = tuning or WallEvidenceParams()
    values, along = frame_walls[:, axis], frame_walls[:, 1 - axis]
    edges = np.arange(values.min() - 2 * tuning.plane_bin, values.max() + 3 * tuning.plane_bin,
                      tuning.plane_bin)
    window = 2 * round(tuning.plane_width / tuning.plane_bin) + 1  # odd: centred on its bin
    counts = ndimage.convolve1d(np.histogram(values, edges)[0], np.ones(window, dtype=np.int64),
                                mode='constant')
    centres = (edges[:-1] + edges[1:]) / 2
    least = tuning.min_points_per_metre * tuning.min_plane_length
    # the points around a plane (0.15 to 0.5 m off it): a wall stands out of them
    reach = round(0.5 / tuning.plane_bin)
    ring = _ring(reach, round(0.15 / tuning.plane_bin))
    background = ndimage.convolve1d(counts.astype(np.float64), ring / ring.sum(),
                                    mode='constant')
    peaks = np.flatnonzero((counts >= np.roll(counts, 1)) & (counts >= np.roll(counts, -1)) &
                           (counts >= least) & (counts >= tuning.min_prominence * background))
    planes: list[WallPlane] = []
    for peak in peaks[np.argsort(-counts[peaks], kind='stable')]:
        if any(abs(centres[peak] - plane.offset) < tuning.min_plane_spacing for plane in planes):
            continue
        # the peak of the box sums may sit anywhere on a plateau as wide as the box
        slab = np.abs(values - centres[peak]) < 2 * tuning.plane_width
        offset = float(np.median(values[slab]))
        slab = np.abs(values - offset) < tuning.plane_width
        span = float(np.ptp(along)) + tuning.plane_step
        clutter = tuning.min_prominence * background[peak] * tuning.plane_step / span
        intervals = _covered_intervals(along[slab], max(2.0, clutter), tuning)
        if len(intervals) and (intervals[:, 1] - intervals[:, 0]).max() >= \
                tuning.min_plane_length:
            planes.append(WallPlane(axis, offset, intervals))
    return planes


def _ring(outer: int, inner: int) -> np.ndarray:
    """A 1D filter footprint: the bins from ``inner`` to ``outer`` away on either side."""
    offsets = np.abs(np.arange(-outer, outer + 1))
    return (offsets >= inner).astype(np.float64)


def _covered_intervals(along: np.ndarray, least: float,
                       tuning: WallEvidenceParams) -> np.ndarray:
    """Stretches of a line that its points cover: ``plane_step`` steps holding ``least``
    points and ``min_points_per_metre`` at least, gaps up to ``plane_gap`` bridged, pieces
    shorter than ``min_plane_length`` left out."""
    steps, counts = np.unique(np.floor(along / tuning.plane_step).astype(np.int64),
                              return_counts=True)
    steps = steps[counts >= max(least, tuning.min_points_per_metre * tuning.plane_step)]
    if len(steps) == 0:
        return np.zeros((0, 2))
    breaks = np.flatnonzero(np.diff(steps) * tuning.plane_step > tuning.plane_gap + 1e-9)
    starts = steps[np.concatenate([[0], breaks + 1])] * tuning.plane_step
    ends = (steps[np.concatenate([breaks, [len(steps) - 1]])] + 1) * tuning.plane_step
    keep = ends - starts >= min(tuning.min_plane_length, 2 * tuning.plane_gap)
    return np.column_stack([starts[keep], ends[keep]])


class Footprint:
    """The plan cells the points occupy, closed and hole-filled, with area queries."""

    def __init__(self, frame_xy: np.ndarray, cell: float):
        self.cell = cell
        self.low = frame_xy.min(axis=0) - 2 * cell
        keys = np.floor((frame_xy - self.low) / cell).astype(np.int64)
        grid = np.zeros(keys.max(axis=0) + 3, dtype=bool)
        grid[keys[:, 0], keys[:, 1]] = True
        square = np.ones((3, 3), dtype=bool)
        labels, _ = ndimage.label(grid, square)
        sizes = np.bincount(labels.ravel())
        grid &= sizes[labels] >= 6  # stray points
        kept = frame_xy[grid[keys[:, 0], keys[:, 1]]]
        self.low_point, self.high_point = kept.min(axis=0), kept.max(axis=0)
        grid = ndimage.binary_fill_holes(ndimage.binary_closing(grid, square, iterations=3))
        self.grid = grid
        self.summed = np.pad(grid.astype(np.int64).cumsum(0).cumsum(1), ((1, 0), (1, 0)))

    def extent(self) -> tuple[np.ndarray, np.ndarray]:
        """Lowest and highest plan coordinates of the points, stray points left out."""
        return self.low_point, self.high_point

    def cover(self, x0: float, x1: float, y0: float, y1: float) -> float:
        """Share of the rectangle [x0, x1] x [y0, y1] that the footprint covers."""
        i0, i1 = (np.clip(np.round((np.array([x0, x1]) - self.low[0]) / self.cell), 0,
                          self.grid.shape[0]).astype(int))
        j0, j1 = (np.clip(np.round((np.array([y0, y1]) - self.low[1]) / self.cell), 0,
                          self.grid.shape[1]).astype(int))
        total = (x1 - x0) * (y1 - y0) / self.cell**2
        if total <= 0:
            return 0.0
        inside = self.summed[i1, j1] - self.summed[i0, j1] - self.summed[i1, j0] + \
            self.summed[i0, j0]
        return float(min(1.0, inside / total))

    def held_share(self, polygon: np.ndarray) -> float:
        """Share of the footprint's area inside a polygon."""
        ix, iy = np.nonzero(self.grid)
        occupied = self.low + (np.column_stack([ix, iy]) + 0.5) * self.cell
        return float(points_in_polygon(occupied, polygon).mean())

    def spanned_share(self, polygon: np.ndarray) -> float:
        """Share of a polygon's area that the convex hull of the footprint spans (the part
        of the room that a view of it sees)."""
        ix, iy = np.nonzero(self.grid)
        occupied = self.low + (np.column_stack([ix, iy]) + 0.5) * self.cell
        hull = occupied[ConvexHull(occupied).vertices]
        ix, iy = np.nonzero(np.ones_like(self.grid))
        centres = self.low + (np.column_stack([ix, iy]) + 0.5) * self.cell
        held = centres[points_in_polygon(centres, polygon)]
        return float(points_in_polygon(held, hull).mean()) if len(held) else 0.0


def _cut_positions(planes: list[WallPlane], axis: int, low: float, high: float,
                   min_edge: float) -> np.ndarray:
    """Where cells are cut across ``axis``: the planes within ``min_edge`` of the footprint's
    extent, longest first, each at least ``min_edge`` from the ones taken, then the extent's
    ends unless a plane lies that near them."""
    cuts: list[float] = []
    for plane in sorted((plane for plane in planes if plane.axis == axis),
                        key=lambda plane: -plane.length):
        if low - min_edge <= plane.offset <= high + min_edge and \
                all(abs(plane.offset - cut) >= min_edge for cut in cuts):
            cuts.append(plane.offset)
    for end in (low, high):
        if all(abs(end - cut) >= min_edge for cut in cuts):
            cuts.append(end)
    return np.array(sorted(cuts))


def _label_cells(cuts: list[np.ndarray], planes: list[WallPlane], footprint: Footprint,
                 tuning: WallEvidenceParams) -> np.ndarray:
    """Inside (True) or outside for every cell between the cuts: a minimum cut of the cost of
    leaving out covered area, taking in uncovered area and bounding the room where no wall
    point backs the boundary. Of the inside regions, the one holding most covered area is
    kept, holes filled."""
    xs, ys = cuts
    areas = np.outer(np.diff(xs), np.diff(ys))
    covered = np.array([[footprint.cover(xs[i], xs[i + 1], ys[j], ys[j + 1])
                         for j in range(len(ys) - 1)] for i in range(len(xs) - 1)])
    covered = areas * covered.reshape(areas.shape)
    # the unbacked length of every cell side: across x (i, j) is the side at xs[i] of the
    # cells (i - 1, j) and (i, j); across y likewise
    across_x = np.array([[_open_length(planes, 0, x, ys[j], ys[j + 1], tuning.plane_width)
                          for j in range(len(ys) - 1)] for x in xs]).reshape(len(xs), -1)
    across_y = np.array([[_open_length(planes, 1, y, xs[i], xs[i + 1], tuning.plane_width)
                          for y in ys] for i in range(len(xs) - 1)]).reshape(-1, len(ys))
    inside = _minimum_cut(covered, tuning.unseen_weight * (areas - covered),
                          tuning.boundary_weight * across_x, tuning.boundary_weight * across_y)
    full = (np.broadcast_to(np.diff(ys), across_x.shape),
            np.broadcast_to(np.diff(xs)[:, None], across_y.shape))
    inside = _fill_unbacked_pockets(inside, full, (full[0] - across_x, full[1] - across_y),
                                    tuning.min_pocket_backing)
    labels, count = ndimage.label(inside)
    if count == 0:
        return inside
    held = ndimage.sum_labels(covered, labels, index=np.arange(1, count + 1))
    return ndimage.binary_fill_holes(labels == 1 + int(np.argmax(held)))


def _fill_unbacked_pockets(inside: np.ndarray, full: tuple[np.ndarray, np.ndarray],
                           backed: tuple[np.ndarray, np.ndarray], least: float) -> np.ndarray:
    """``inside`` and every outside cell reached from it across cell sides that wall points
    back less than ``least`` of (cell to cell): notches that the view's occlusions cut, not
    the room's walls. ``full`` and ``backed`` hold the lengths and backed lengths of the cell
    sides across x ((nx + 1, ny)) and across y ((nx, ny + 1))."""
    open_x = backed[0][1:-1] < least * full[0][1:-1]  # inner sides only: (nx - 1, ny)
    open_y = backed[1][:, 1:-1] < least * full[1][:, 1:-1]
    reached = inside.copy()
    while True:
        grown = reached.copy()
        grown[1:] |= reached[:-1] & open_x
        grown[:-1] |= reached[1:] & open_x
        grown[:, 1:] |= reached[:, :-1] & open_y
        grown[:, :-1] |= reached[:, 1:] & open_y
        if (grown == reached).all():
            return reached
        reached = grown


def _minimum_cut(outside_cost: np.ndarray, inside_cost: np.ndarray, across_x: np.ndarray,
                 across_y: np.ndarray) -> np.ndarray:
    """The inside/outside labels of a grid of cells of least total cost: ``outside_cost`` and
    ``inside_cost`` per cell, ``across_x`` (nx + 1, ny) and ``across_y`` (nx, ny + 1) for a
    boundary on each cell side (the outer sides bound the room when their cell is inside).
    """
    nx, ny = outside_cost.shape
    index = np.arange(nx * ny).reshape(nx, ny)
    source, sink = nx * ny, nx * ny + 1
    outer = inside_cost.copy()
    outer[0] += across_x[0]
    outer[-1] += across_x[-1]
    outer[:, 0] += across_y[:, 0]
    outer[:, -1] += across_y[:, -1]
    tails = [np.full(nx * ny, source), index.ravel(),
             index[:-1].ravel(), index[1:].ravel(), index[:, :-1].ravel(), index[:, 1:].ravel()]
    heads = [index.ravel(), np.full(nx * ny, sink),
             index[1:].ravel(), index[:-1].ravel(), index[:, 1:].ravel(), index[:, :-1].ravel()]
    costs = [outside_cost.ravel(), outer.ravel(), across_x[1:-1].ravel(), across_x[1:-1].ravel(),
             across_y[:, 1:-1].ravel(), across_y[:, 1:-1].ravel()]
    scale = 1000.0  # integer capacities: thousandths of a square metre
    graph = csr_matrix((np.round(np.concatenate(costs) * scale).astype(np.int32),
                        (np.concatenate(tails), np.concatenate(heads))),
                       shape=(nx * ny + 2, nx * ny + 2))
    residual = graph - maximum_flow(graph, source, sink).flow
    residual.data = (residual.data > 0).astype(np.int8)
    residual.eliminate_zeros()
    reached = breadth_first_order(residual, source, directed=True, return_predecessors=False)
    inside = np.zeros(nx * ny + 2, dtype=bool)
    inside[reached] = True
    return inside[:nx * ny].reshape(nx, ny)


def _open_length(planes: list[WallPlane], axis: int, offset: float, start: float, end: float,
                 width: float) -> float:
    """Length of the segment from ``start`` to ``end`` on the line across ``axis`` at
    ``offset`` that no wall plane backs."""
    return (end - start) * (1.0 - _backed_share(planes, axis, offset, start, end, width))


def _backed_share(planes: list[WallPlane], axis: int, offset: float, start: float, end: float,
                  width: float) -> float:
    """Share of a segment of the line across ``axis`` at ``offset`` that wall planes back."""
    if end - start <= 1e-9:
        return 0.0
    pieces = [plane.intervals for plane in planes
              if plane.axis == axis and abs(plane.offset - offset) < width]
    if not pieces:
        return 0.0
    intervals = np.clip(np.concatenate(pieces), start, end)
    intervals = intervals[np.argsort(intervals[:, 0])]
    covered, reach = 0.0, start
    for low, high in intervals:
        low = max(low, reach)
        if high > low:
            covered += high - low
            reach = high
    return covered / (end - start)


def _edge_support(a: np.ndarray, b: np.ndarray, planes: list[WallPlane], width: float) -> float:
    """Share of the edge from ``a`` to ``b`` (parallel to an axis) that wall planes back."""
    axis = 0 if abs(b[0] - a[0]) < abs(b[1] - a[1]) else 1  # 0: the edge runs along y
    start, end = sorted((a[1 - axis], b[1 - axis]))
    if not math.isclose(a[axis], b[axis], abs_tol=width):
        return 0.0
    return _backed_share(planes, axis, (a[axis] + b[axis]) / 2, start, end, width)


def walls_first_outline(xyz: np.ndarray, levels: Levels, to_frame: np.ndarray,
                        failure: str | None, params: CornerParams) -> WalledOutline | None:
    """The outline built on the walls (:func:`walled_outline`) of points ``xyz`` (levels
    ``levels``; ``to_frame`` turns the plan into the wall-aligned frame), for a scan whose
    traced footprint outline is partial; None when there is none or it is a view of less
    than half the room: the points span less than ``min_seen_area`` of it, or it holds less
    than ``min_held`` of their footprint. ``failure`` says why the traced outline is no room
    (then there is nothing to keep): :class:`CornerDetectionError` with it instead of None.
    Its wall evidence reaches ``evidence_reach`` up (a reconstruction's walls often stop low).
    """
    tuning = WallEvidenceParams()
    evidence = wall_points(xyz, levels, replace(params, wall_reach=tuning.evidence_reach))
    walled = None
    if len(evidence) >= 100:
        walled = walled_outline(xyz[:, :2] @ to_frame.T, evidence @ to_frame.T, params, tuning)
    if walled is None:
        problem = 'no outline could be built on its wall planes'
    elif walled.seen_area < tuning.min_seen_area or walled.held < tuning.min_held:
        problem = (f'the outline built on the wall planes is a view of less than half the room '
                   f'(the points span {walled.seen_area:.0%} of it, it holds {walled.held:.0%} '
                   f'of their footprint; need {tuning.min_seen_area:.0%} and '
                   f'{tuning.min_held:.0%})')
    else:
        return walled
    if failure is not None:
        raise CornerDetectionError(f'{failure}, and {problem}')
    return None
