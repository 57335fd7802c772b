"""Simulated LiDAR: the paper's sensor path and ray scheme, cast in batches on Embree
(:mod:`generator.embree`).

Knows nothing of Blender: it takes triangle arrays (world frame) where every triangle carries a
color and the index of the part (annotated element) it belongs to.

Paper, Sec. 3.1: the sensor moves along two crossing segments covering 80 % of the room, in a
random direction, at 2/3 of the room height (L-, U- and T-shaped rooms get such a cross in each
cell of their grid, see :func:`sensor_path`); ray directions are uniformly random; rays first go
to the movable objects only (the room excluded) until the requested share of object points is
reached, then to the structure (objects still occlude it, so no wall points appear behind a sofa).

Object rays are aimed by default (``aim_at_objects``): each goes from the sensor towards a uniform
random point in the bounds of a random object (picked with probability proportional to its bounds'
surface area), which is how a per-object ``ray_cast`` target is chosen; in a large room, uniform
sphere directions hit objects with only 1-2 % of rays. ``aim_at_objects: false`` casts uniform
directions for both phases.
Noise models (off by default): range noise, angular jitter and per-point dropout.

Glass (triangles of ``glass_colors``) lets a ray through with probability
``glass_transmission``, drawn once per ray: a ray that passes goes on through every glass face
on its way (both faces of a pane) to the first opaque surface behind, as a time-of-flight beam
crosses clear glass; one that does not returns from the first glass face.
"""
import os
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numba
import numpy as np

from generator.counter_random import DRAW_CHUNK, normals, stream_seed, uniform
from generator.embree import TriangleMeshScene, first_hits
from synthdet.geometry import grid_cells


@dataclass
class TriangleScene:
    """Triangles of a room: world vertices, per-triangle color and part index."""

    vertices: np.ndarray  # (V, 3) float64
    triangles: np.ndarray  # (T, 3) int32
    colors: np.ndarray  # (T, 3) uint8
    part: np.ndarray  # (T,) int32, index into the caller's part list
    movable: np.ndarray  # (P,) bool per part: True for detection objects


@dataclass
class ScanResult:
    """Labelled points, in ray order: first the object points, then the structure points."""

    xyz: np.ndarray  # (N, 3) float64
    rgb: np.ndarray  # (N, 3) uint8
    part: np.ndarray  # (N,) int32
    triangle: np.ndarray  # (N,) int64, index of the hit triangle in the TriangleScene
    origin: np.ndarray  # (N, 3) float32, the sensor position each point was seen from
    rays_cast: int
    object_points: int
    # (N,) bool: returns in the air between two surfaces (TLS mixed pixels); None: there are none
    stray: np.ndarray | None = None


def _chord(polygon: np.ndarray, origin: np.ndarray, direction: np.ndarray) -> tuple[float, float]:
    """Parameters (t_min < 0 < t_max) where the line origin + t * direction leaves the polygon."""
    p0, p1 = polygon, np.roll(polygon, -1, axis=0)
    edge = p1 - p0
    denom = direction[0] * edge[:, 1] - direction[1] * edge[:, 0]
    rel = p0 - origin
    with np.errstate(divide='ignore', invalid='ignore'):
        t = (rel[:, 0] * edge[:, 1] - rel[:, 1] * edge[:, 0]) / denom
        s = (rel[:, 0] * direction[1] - rel[:, 1] * direction[0]) / denom
    valid = (np.abs(denom) > 1e-12) & (s >= 0) & (s <= 1)
    t = t[valid]
    return float(t[t < 0].max()), float(t[t > 0].min())


def sensor_path(polygon: np.ndarray,
                height: float,
                rng: np.random.Generator,
                coverage: float = 0.8,
                height_fraction: float = 2 / 3,
                steps: int = 512,
                cells: list[np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Sensor positions (steps, 3) and the segments (S, 2, 2) they run along, in order.

    The paper's path: two segments at right angles, crossing at the centre at a random angle,
    each spanning ``coverage`` of the room's extent along its line. A rectangle gets exactly
    that. An L-, U- or T-shaped room gets such a cross in every cell of :func:`grid_cells`, so
    that the sensor also walks into the arms (a single cross leaves an arm's inner walls
    unscanned). A hall passes its bays as ``cells``: a cross in each bay. Each segment is
    clipped to the room; the steps are shared equally by the segments.
    """
    segments = []
    for cell in grid_cells(polygon) if cells is None else cells:
        origin = (cell.min(axis=0) + cell.max(axis=0)) / 2
        angle = rng.uniform(0.0, np.pi)
        for a in (angle, angle + np.pi / 2):
            direction = np.array([np.cos(a), np.sin(a)])
            c0, c1 = _chord(cell, origin, direction)
            r0, r1 = _chord(polygon, origin, direction)
            t0, t1 = max(c0, r0), min(c1, r1)
            mid, half = (t0 + t1) / 2, coverage * (t1 - t0) / 2
            segments.append([origin + direction * (mid - half), origin + direction * (mid + half)])
    segments = np.array(segments)
    counts = [len(chunk) for chunk in np.array_split(np.arange(steps), len(segments))]
    xy = np.concatenate([
        start + np.linspace(0, 1, n)[:, None] * (end - start)
        for (start, end), n in zip(segments, counts)
    ])
    z = np.full((steps, 1), height_fraction * height)
    return np.concatenate([xy, z], axis=1), segments


def random_directions(rng: np.random.Generator, n: int) -> np.ndarray:
    """Unit vectors uniformly distributed on the sphere."""
    d = rng.standard_normal((n, 3))
    return d / row_norms(d)


def row_norms(v: np.ndarray) -> np.ndarray:
    """Euclidean norms (N, 1) of the rows of ``v`` (N, 3).

    The same bits as ``np.linalg.norm(v, axis=1, keepdims=True)``, which sums the squares in
    this order, but computed column by column, 5-8x faster than numpy's short-axis reduction.
    """
    x, y, z = v[:, 0], v[:, 1], v[:, 2]
    return np.sqrt((x * x + y * y) + z * z)[:, None]


def triangles_of_colors(scene: TriangleScene, colors: Sequence[Sequence[int]]) -> np.ndarray:
    """Per triangle (T,): is its color one of ``colors`` (RGB triples; none: all False)."""
    if not len(colors):
        return np.zeros(len(scene.triangles), dtype=bool)
    wanted = np.asarray(colors, np.uint8)
    return (scene.colors[:, None, :] == wanted[None]).all(axis=2).any(axis=1)


def part_bounds(scene: TriangleScene, parts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned bounds (P, 3) low and high of the triangles of each of ``parts``, in one
    pass over the triangles (inf / -inf for a part without triangles)."""
    corners = scene.vertices[scene.triangles]  # (T, 3, 3)
    row = np.full(int(scene.part.max(initial=-1)) + 1, -1)
    row[parts] = np.arange(len(parts))
    rows = row[scene.part]
    mine = rows >= 0
    low = np.full((len(parts), 3), np.inf)
    high = np.full((len(parts), 3), -np.inf)
    np.minimum.at(low, rows[mine], corners[mine].min(axis=1))
    np.maximum.at(high, rows[mine], corners[mine].max(axis=1))
    return low, high


# rays per casting thread a sensor model casts at a time (see :meth:`Scanner.slice_size`)
CACHE_SLICE = 32768
# fewer rays than this per thread are cast on one thread (starting threads would cost more)
_MIN_SLICE = 16_384
# a ray that passes a glass face goes on from this far (metres) behind it
_GLASS_STEP = 1e-4
# glass faces one ray passes at most (a pane has two)
_MAX_GLASS_FACES = 16


# no triangle map: the hit triangles are the scene's own
_NO_MAP = np.zeros(0, dtype=np.int64)
# no stray returns (see :func:`label_returns`)
NO_STRAY = np.zeros(0, dtype=bool)


@numba.njit(cache=True, nogil=True, inline='always')
def _write_ray(ray: int, path: np.ndarray, step: int, x: float, y: float, z: float, norm: float,
               origins: np.ndarray, directions: np.ndarray, cast_origins: np.ndarray,
               cast_directions: np.ndarray) -> None:
    """Row ``ray`` of a batch: the origin ``path[step]``, the direction ``(x, y, z) / norm``,
    and their float32 copies, which Embree casts."""
    directions[ray, 0], directions[ray, 1] = x / norm, y / norm
    directions[ray, 2] = z / norm
    for axis in range(3):
        origins[ray, axis] = path[step, axis]
        cast_origins[ray, axis] = origins[ray, axis]
        cast_directions[ray, axis] = directions[ray, axis]


@numba.njit(cache=True, nogil=True)
def path_rays(path: np.ndarray, start: int, seed: np.uint64, origins: np.ndarray,
              directions: np.ndarray, cast_origins: np.ndarray,
              cast_directions: np.ndarray) -> None:
    """Write a batch of uniform rays: origins (N, 3) going round ``path`` from ``start``, unit
    directions (N, 3) of three standard normal draws each, normalised as
    :func:`random_directions` does, and their float32 copies, which Embree casts. Ray r's
    draws are those of the items 3r, 3r + 1, 3r + 2 of the stream ``seed``
    (:data:`generator.counter_random.ITEM_COUNTERS`), chunk by chunk
    (:func:`generator.counter_random.normals`)."""
    draws = np.empty(3 * DRAW_CHUNK)
    step = start % len(path)
    for first in range(0, len(origins), DRAW_CHUNK):
        stop = min(first + DRAW_CHUNK, len(origins))
        normals(seed, 3 * first, 3 * stop, 0, draws)
        for ray in range(first, stop):
            own = 3 * (ray - first)
            x, y, z = draws[own], draws[own + 1], draws[own + 2]
            _write_ray(ray, path, step, x, y, z, np.sqrt((x * x + y * y) + z * z), origins,
                       directions, cast_origins, cast_directions)
            step += 1
            if step == len(path):
                step = 0


# up to this many targets, an aimed ray's target is found by counting the cumulative shares below
# its draw, else by a binary search
_COUNTED_TARGETS = 512


@numba.njit(cache=True, nogil=True)
def aimed_rays(path: np.ndarray, start: int, cumulative: np.ndarray, low: np.ndarray,
               extent: np.ndarray, seed: np.uint64, origins: np.ndarray,
               directions: np.ndarray, cast_origins: np.ndarray,
               cast_directions: np.ndarray) -> None:
    """Write a batch of aimed rays: origins (N, 3) going round ``path`` from ``start``, unit
    directions (N, 3) towards a uniform random point ``low + uniform * extent`` of a random
    target's bounds (target k with probability ``cumulative[k] - cumulative[k - 1]``), as
    ``(point - origin) / (row_norms + 1e-12)`` computes them, and their float32 copies, which
    Embree casts. Ray r draws the uniforms 4r to 4r + 3 of the stream ``seed``
    (:mod:`generator.counter_random`): its target, then its point."""
    last = len(cumulative) - 1
    for ray in range(len(origins)):
        step = (start + ray) % len(path)
        counter = np.uint64(4 * ray)
        draw = uniform(seed, counter)
        if last < _COUNTED_TARGETS:
            # the targets whose cumulative share is at most the draw, counted without a branch
            # (a binary search mispredicts about every other step)
            box = 0
            for target in range(last):
                box += cumulative[target] <= draw
        else:
            box = min(np.searchsorted(cumulative, draw, side='right'), last)
        x = (low[box, 0] + uniform(seed, counter + np.uint64(1)) * extent[box, 0]) - path[step, 0]
        y = (low[box, 1] + uniform(seed, counter + np.uint64(2)) * extent[box, 1]) - path[step, 1]
        z = (low[box, 2] + uniform(seed, counter + np.uint64(3)) * extent[box, 2]) - path[step, 2]
        _write_ray(ray, path, step, x, y, z, np.sqrt((x * x + y * y) + z * z) + 1e-12, origins,
                   directions, cast_origins, cast_directions)


@numba.njit(cache=True, nogil=True)
def _returns(t_hit: np.ndarray, primitive: np.ndarray, kept: np.ndarray, movable_tri: np.ndarray,
             tri_map: np.ndarray, keep_movable: bool,
             most: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows (ascending) and scene triangles of a batch's returns: finite hits, kept (``kept``
    empty: all), mapped through ``tri_map`` (empty: none), on the structure only unless
    ``keep_movable``; the first ``most`` of them."""
    wanted = min(len(t_hit), max(most, 0))
    # one place more: each ray is written to the next place, which it keeps when it is a
    # return (no branch on a ray's hit)
    rows = np.empty(wanted + 1, dtype=np.int64)
    triangles = np.empty(wanted + 1, dtype=np.int64)
    count = 0
    for ray in range(len(t_hit)):
        if count == wanted:
            break
        hit = np.isfinite(t_hit[ray])
        if len(kept):
            hit &= kept[ray]
        triangle = np.int64(primitive[ray]) if hit else np.int64(0)  # a miss has none
        if len(tri_map):
            triangle = tri_map[triangle]
        rows[count], triangles[count] = ray, triangle
        count += hit & (keep_movable | (not movable_tri[triangle]))
    return rows[:count], triangles[:count]


@numba.njit(cache=True, nogil=True)
def _return_points(origins: np.ndarray, directions: np.ndarray, t_hit: np.ndarray,
                   rows: np.ndarray, noise: np.ndarray, xyz: np.ndarray,
                   origin: np.ndarray) -> None:
    """Write the points of ``rows`` at origin + direction x distance (the float32 hit distance
    as float64, plus ``noise`` (N,) where given) into ``xyz`` (N, 3) and their origins into
    ``origin`` (N, 3, float32)."""
    for k in range(len(rows)):
        ray = rows[k]
        distance = np.float64(t_hit[ray])
        if len(noise):
            distance = distance + noise[k]
        for axis in range(3):
            xyz[k, axis] = origins[ray, axis] + directions[ray, axis] * distance
            origin[k, axis] = origins[ray, axis]


@numba.njit(cache=True, nogil=True)
def _glass_hits(t_hit: np.ndarray, primitive: np.ndarray, glass: np.ndarray) -> np.ndarray:
    """Rows (ascending) of a batch whose hit (finite ``t_hit``) is on a ``glass`` triangle."""
    rows = np.empty(len(t_hit), dtype=np.int64)
    count = 0
    for ray in range(len(t_hit)):
        if np.isfinite(t_hit[ray]) and glass[primitive[ray]]:
            rows[count] = ray
            count += 1
    return rows[:count].copy()


@numba.njit(cache=True, nogil=True)
def label_returns(triangle: np.ndarray, colors: np.ndarray, part_of: np.ndarray,
                  movable_tri: np.ndarray, stray: np.ndarray, rgb: np.ndarray, part: np.ndarray,
                  triangles: np.ndarray) -> int:
    """Write each return's color, part and triangle (int64) in one pass; returns the number
    of returns on objects, ``stray`` ones (empty: none) left out."""
    object_points = 0
    for k in range(len(triangle)):
        index = triangle[k]
        rgb[k, 0], rgb[k, 1], rgb[k, 2] = colors[index, 0], colors[index, 1], colors[index, 2]
        part[k] = part_of[index]
        triangles[k] = index
        object_points += movable_tri[index] and not (len(stray) and stray[k])
    return object_points


class Scanner:
    """Casts the paper's ray scheme on a :class:`TriangleScene` with Embree scenes
    (:mod:`generator.embree`)."""

    def __init__(self,
                 scene: TriangleScene,
                 threads: int = 0,
                 glass_colors: Sequence[Sequence[int]] = (),
                 glass_transmission: float = 0.0):
        self.scene = scene
        self.threads = threads
        self.glass_transmission = float(glass_transmission)
        # per triangle: glass, which a ray passes with probability glass_transmission
        self.glass_tri = triangles_of_colors(scene, glass_colors)
        # per triangle: does it belong to a movable part (one lookup when labelling hits)
        self.movable_tri = scene.movable[scene.part]
        self.object_tri = np.flatnonzero(self.movable_tri)
        # axis-aligned bounds of each movable part: the targets of aimed object rays
        self.targets = np.flatnonzero(scene.movable)
        self.target_lo, self.target_hi = part_bounds(scene, self.targets)
        self.target_extent = self.target_hi - self.target_lo
        extent = self.target_extent
        area = 2 * (
            extent[:, 0] * extent[:, 1] + extent[:, 1] * extent[:, 2] +
            extent[:, 0] * extent[:, 2])
        # a target's probability is its share of the bounds' surface area, drawn by inverting
        # the cumulative shares
        self.target_cumulative = np.cumsum(area / area.sum() if len(area) else area)
        self.full_scene = self._embree(scene.triangles)
        self.object_scene = self._embree(scene.triangles[self.object_tri]) if len(
            self.object_tri) else None
        # the glass triangles in the objects-only scene's triangle order
        self._object_glass_tri = self.glass_tri[self.object_tri]

    def slice_size(self, batch: int) -> int:
        """Rays a sensor model casts at a time out of a batch of ``batch``: at most
        ``CACHE_SLICE`` per casting thread, so that a slice's rays and hits stay in the cores'
        caches (each ray is cast on its own: slicing a batch changes no hit)."""
        return min(batch, CACHE_SLICE * (self.threads or os.cpu_count() or 1))

    def _embree(self, triangles: np.ndarray) -> TriangleMeshScene:
        # Embree's default mode, faster per ray than the robust mode Open3D sets; the benchmark
        # prints the agreement of the two (docs/generator.md, "Speed")
        return TriangleMeshScene(self.scene.vertices, triangles)

    def cast(self,
             raycaster,
             origins: np.ndarray,
             directions: np.ndarray,
             rng: np.random.Generator | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Hits of a batch: distance (inf for a miss) and triangle index in that scene.

        The distance is float32 in units of the direction's length, the index uint32 (the
        largest uint32 for a miss). Each ray is cast on its own, so the result of a ray does not
        depend on the batch or on the thread count; ``threads`` > 1 (0: all cores) casts
        contiguous slices of the batch in parallel (the cast releases the GIL). With ``rng`` and a
        ``glass_transmission`` above 0, a ray whose first hit is glass passes it with that
        probability (one draw per such ray) and returns from the first opaque surface behind.
        """
        t_hit, primitive = self._first_hits(raycaster, origins, directions)
        if rng is None or self.glass_transmission <= 0.0:
            return t_hit, primitive
        glass = self.glass_tri if raycaster is self.full_scene else self._object_glass_tri
        rows = _glass_hits(t_hit, primitive, glass)
        rows = rows[rng.random(len(rows)) < self.glass_transmission]
        if not len(rows):
            return t_hit, primitive
        # only the passing rays, in float32 as cast (the same values as converting the batch)
        origins = np.take(origins, rows, axis=0).astype(np.float32, copy=False)
        directions = np.take(directions, rows, axis=0).astype(np.float32, copy=False)
        for _ in range(_MAX_GLASS_FACES):
            if not len(rows):
                break
            step = _GLASS_STEP / np.linalg.norm(directions, axis=1)
            travelled = t_hit[rows] + step
            behind = origins + directions * travelled[:, None]
            t_next, p_next = self._first_hits(raycaster, behind, directions)
            t_hit[rows], primitive[rows] = travelled + t_next, p_next
            passing = np.flatnonzero(np.isfinite(t_next))
            passing = passing[glass[p_next[passing]]]
            rows, origins, directions = rows[passing], origins[passing], directions[passing]
        return t_hit, primitive

    def _first_hits(self, raycaster, origins: np.ndarray,
                    directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Embree's first hits of a batch (see :meth:`cast`), sliced over the threads."""
        origins = np.asarray(origins, dtype=np.float32)
        directions = np.asarray(directions, dtype=np.float32)
        count = len(origins)
        workers = min(self.threads or os.cpu_count() or 1, max(1, count // _MIN_SLICE))
        t_hit, primitive = np.empty(count, dtype=np.float32), np.empty(count, dtype=np.int32)
        if workers == 1:
            first_hits(raycaster, origins, directions, t_hit, primitive)
        else:
            # each thread casts a contiguous slice into its part of the outputs
            edges = [count * k // workers for k in range(workers + 1)]

            def cast_slice(start: int, stop: int) -> None:
                first_hits(raycaster, origins[start:stop], directions[start:stop],
                           t_hit[start:stop], primitive[start:stop])

            with ThreadPoolExecutor(workers) as pool:
                list(pool.map(cast_slice, edges[:-1], edges[1:]))
        # a miss is -1 in int32, the same bits as Open3D's invalid id in uint32
        return t_hit, primitive.view(np.uint32)

    def scan(self, path: np.ndarray, n_points: int, object_ratio: float, rng: np.random.Generator,
             config: Mapping[str, Any]) -> ScanResult:
        """Collect ``n_points`` labelled points, ``object_ratio`` of them on movable objects."""
        target_objects = int(round(object_ratio *
                                   n_points)) if self.object_scene is not None else 0
        rays = _PathRays(self, path, n_points, rng, config)
        got_objects = 0
        if target_objects > 0:
            got_objects = rays.collect(
                self.object_scene,
                self.object_tri,
                target_objects,
                True,
                int(config['max_object_rays']),
                aimed=bool(config['aim_at_objects']))
            if got_objects < target_objects:
                warnings.warn(f'only {got_objects} of {target_objects} object points after '
                              f'{config["max_object_rays"]} ray batches; the rest goes to the '
                              f'structure')
        remaining = n_points - got_objects
        max_batches = max(64, 8 * remaining // rays.batch + 64)
        got = rays.collect(self.full_scene, None, remaining, False, max_batches)
        if got < remaining:
            warnings.warn(f'only {got_objects + got} of {n_points} points: most rays escape the '
                          f'scene (is the room closed?)')
        count = rays.points
        xyz, origin, tri = rays.xyz[:count], rays.origin[:count], rays.tri[:count]
        rgb, part = np.empty((count, 3), dtype=np.uint8), np.empty(count, dtype=np.int32)
        label_returns(tri, self.scene.colors, self.scene.part, self.movable_tri, NO_STRAY, rgb,
                      part, tri)
        return ScanResult(
            xyz=xyz,
            rgb=rgb,
            part=part,
            triangle=tri,
            origin=origin,
            rays_cast=rays.rays_cast,
            object_points=got_objects)


class _PathRays:
    """The rays of one :meth:`Scanner.scan`, batch after batch from the points of its path, and
    the returns they collect, written in place in ray order."""

    def __init__(self, scanner: Scanner, path: np.ndarray, n_points: int,
                 rng: np.random.Generator, config: Mapping[str, Any]) -> None:
        self.scanner, self.path, self.rng, self.config = scanner, path, rng, config
        self.batch = batch = int(config['batch_rays'])
        self.xyz = np.empty((n_points, 3))
        self.origin = np.empty((n_points, 3), dtype=np.float32)
        self.tri = np.empty(n_points, dtype=np.int64)
        self.rays_cast, self.step, self.points = 0, 0, 0
        # one batch's rays (float64, and the float32 copies Embree casts), reused by every batch
        self.origins, self.nominal = np.empty((batch, 3)), np.empty((batch, 3))
        self.rays = (self.origins, self.nominal, np.empty((batch, 3), dtype=np.float32),
                     np.empty((batch, 3), dtype=np.float32))

    def collect(self, raycaster, tri_map: np.ndarray | None, wanted: int, keep_movable: bool,
                max_batches: int, aimed: bool = False) -> int:
        """Cast at most ``max_batches`` batches into ``raycaster`` until ``wanted`` returns
        (``keep_movable``: on movable objects, else on the rest) are collected; returns how
        many were."""
        config, rng = self.config, self.rng
        got = 0
        for _ in range(max_batches):
            if got >= wanted:
                break
            t_hit, prim = self._cast_batch(raycaster, aimed)
            kept = (rng.random(self.batch) >= config['dropout']
                    if config['dropout'] > 0 else np.ones(0, dtype=bool))
            # the returns' rows and labels (a miss has no primitive), at most the rest wanted
            rows, labels = _returns(t_hit, prim, kept, self.scanner.movable_tri,
                                    _NO_MAP if tri_map is None else tri_map, keep_movable,
                                    wanted - got)
            if len(rows) == 0:
                continue
            noise = (rng.normal(0.0, config['range_noise'], len(rows))
                     if config['range_noise'] > 0 else np.zeros(0))
            first, last = self.points, self.points + len(rows)
            _return_points(self.origins, self.nominal, t_hit, rows, noise, self.xyz[first:last],
                           self.origin[first:last])
            self.tri[first:last] = labels
            self.points = last
            got += len(rows)
        return got

    def _cast_batch(self, raycaster, aimed: bool) -> tuple[np.ndarray, np.ndarray]:
        """The first hits of the next batch of rays: aimed at a random point of a random
        object's bounds (area-weighted) or uniform, with the configured angular jitter."""
        scanner, rng = self.scanner, self.rng
        start = self.step
        self.step = int((self.step + self.batch) % len(self.path))
        if aimed:
            aimed_rays(self.path, start, scanner.target_cumulative, scanner.target_lo,
                       scanner.target_extent, stream_seed(rng), *self.rays)
        else:
            path_rays(self.path, start, stream_seed(rng), *self.rays)
        cast_origins, cast_dirs = self.rays[2:]
        if self.config['angular_jitter'] > 0:
            cast_dirs = self.nominal + rng.standard_normal(
                (self.batch, 3)) * self.config['angular_jitter']
            cast_dirs /= row_norms(cast_dirs)
        t_hit, prim = scanner.cast(raycaster, cast_origins, cast_dirs, rng)
        self.rays_cast += self.batch
        return t_hit, prim
