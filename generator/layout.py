"""Room layouts: the paper's placement rules, as boxes and parameters, in plain numpy.

A layout decides what goes where; it knows nothing of Blender. The rules (paper, Sec. 3.1):

- the room is a parametric box (optionally L- or U-shaped) that holds everything;
- each class has an appearance probability;
- tables and sofas stand along the walls and share that space, at most 4 together;
- chairs go at 4 positions on an inner boundary, each with a random rotation;
- yumis and 3D printers stand only on tables, at most one on each local side
  (left = -x, right = +x).

Beyond the paper: L/U rooms, door/window openings and factory clutter (class ``clutter``,
generator/clutter.py), placed after the detection objects: shelves, cabinets and machines with
their back to a wall, pallets, crates, carts and bins on the floor (often touching an object),
crates on pallets and on free table tops, pipe runs along the walls or under the ceiling.
With ``room_kinds`` in the configuration a room may instead be an office, meeting room, living
room, bedroom or lab, furnished by the rules of generator/room_kinds.py.
No two objects intersect: every placement is checked with oriented-box tests and dropped when no
free position is found after a few tries. Clutter may touch what it stands next to (no
clearance), the detection objects keep ``layout.clearance`` among themselves.

Frames: metres, z up, yaw in radians counter-clockwise from +x. An object's local frame has xy
centred on its bounding box, z = 0 at its lowest point, and its front towards local -y.
"""
import math
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from generator.asset_spec import AssetSpec, Catalog
from generator.clutter import (CLUTTER_KINDS, PRIMITIVE_KINDS, WALL_KINDS, sample_clutter,
                               sample_pipe_run, sample_primitive)
from generator.config import ROOM_KINDS
from synthdet.classes import GENERATED_CLASSES
from synthdet.geometry import (box_corners_xy, edges_cross, points_in_polygon, rotation2d,
                               signed_area)

EPS = 1e-9


def catalog_from_library(library: Any) -> dict[str, list[AssetSpec]]:
    """Build a layout catalog from an asset library; a class the library lacks never appears."""
    catalog = {}
    present = set(library.classes())
    for cls in GENERATED_CLASSES:
        specs = []
        for inst in (library.instances(cls) if cls in present else []):
            top_size = None if inst.top_size is None else tuple(float(v) for v in inst.top_size)
            specs.append(
                AssetSpec(
                    cls=inst.cls,
                    name=inst.name,
                    asset=inst.asset,
                    params=dict(inst.params),
                    size=tuple(float(v) for v in inst.size),
                    top_z=None if inst.top_z is None else float(inst.top_z),
                    top_size=top_size))
        catalog[cls] = specs
    return catalog


@dataclass
class PlacedObject:
    """One object of a room: its asset, oriented box and the instance it stands on."""

    instance: str
    spec: AssetSpec
    center: np.ndarray  # (3,) centre of the oriented bounding box
    yaw: float
    on: str | None = None

    @property
    def cls(self) -> str:
        return self.spec.cls

    @property
    def size(self) -> np.ndarray:
        return np.asarray(self.spec.size, dtype=float)

    @property
    def base(self) -> np.ndarray:
        """Origin of the local frame in the world: box centre in xy, lowest point in z."""
        return np.array([self.center[0], self.center[1], self.center[2] - self.size[2] / 2])

    def box_dict(self) -> dict[str, Any]:
        return {
            'center': [round(float(v), 6) for v in self.center],
            'size': [round(float(v), 6) for v in self.size],
            'yaw': round(float(self.yaw), 6)
        }


@dataclass
class Opening:
    """A door or window cut into wall ``wall`` (polygon edge index), from ``u0`` to ``u1``."""

    kind: str
    wall: int
    u0: float
    u1: float
    z0: float
    z1: float


@dataclass
class Partition:
    """An inner wall of a hall from ``start`` to ``end`` (xy), open between ``u0`` and ``u1``."""

    start: np.ndarray  # (2,)
    end: np.ndarray  # (2,)
    u0: float  # the passage, in metres along the wall from ``start``
    u1: float


@dataclass
class RoomLayout:
    """A room or a hall: clockwise floor polygon, height, openings and objects.

    A hall (``shape == 'hall'``) is also cut into ``bays`` (clockwise rectangles, each furnished
    like a room and scanned by its own cross) and may have inner ``partitions``.
    """

    shape: str
    polygon: np.ndarray  # (N, 2), clockwise seen from above
    height: float
    objects: list[PlacedObject] = field(default_factory=list)
    openings: list[Opening] = field(default_factory=list)
    bays: list[np.ndarray] = field(default_factory=list)
    partitions: list[Partition] = field(default_factory=list)
    kind: str | None = None  # the room kind, when the configuration has ``room_kinds``

    def counts(self) -> dict[str, int]:
        result = {cls: 0 for cls in GENERATED_CLASSES}
        for obj in self.objects:
            if obj.cls in result:
                result[obj.cls] += 1
        return result


# ----------------------------------------------------------------------------- geometry helpers


def rectangles_overlap(a: np.ndarray, b: np.ndarray, clearance: float = 0.0) -> bool:
    """Separating-axis test of two convex quads (4, 2): True if closer than ``clearance``."""
    for quad in (a, b):
        for i in range(4):
            edge = quad[(i + 1) % 4] - quad[i]
            axis = np.array([-edge[1], edge[0]])
            axis /= np.linalg.norm(axis) + EPS
            pa, pb = a @ axis, b @ axis
            if pa.max() + clearance <= pb.min() or pb.max() + clearance <= pa.min():
                return False
    return True


def boxes_intersect(a: PlacedObject, b: PlacedObject, clearance: float = 0.0) -> bool:
    """True if the oriented boxes of ``a`` and ``b`` overlap (or are closer than ``clearance``)."""
    sa, sb = a.spec.size, b.spec.size
    az0, az1 = a.center[2] - sa[2] / 2, a.center[2] + sa[2] / 2
    bz0, bz1 = b.center[2] - sb[2] / 2, b.center[2] + sb[2] / 2
    if az1 <= bz0 + EPS or bz1 <= az0 + EPS:
        return False
    reach = (math.hypot(sa[0], sa[1]) + math.hypot(sb[0], sb[1])) / 2 + clearance
    if math.hypot(a.center[0] - b.center[0], a.center[1] - b.center[1]) >= reach:
        return False  # bounding circles apart
    return rectangles_overlap(
        box_corners_xy(a.center, sa, a.yaw), box_corners_xy(b.center, sb, b.yaw), clearance)


def quad_inside_polygon(quad: np.ndarray, polygon: np.ndarray) -> bool:
    """True if the convex quad lies inside the simple polygon (touching allowed)."""
    if not points_in_polygon(quad, polygon).all():
        return False
    if points_in_polygon(polygon, quad[::-1] if signed_area(quad) < 0 else quad).any():
        return False
    return not edges_cross(quad, polygon, EPS)


def inward_normals(polygon: np.ndarray) -> np.ndarray:
    """Unit inward normal (N, 2) of each edge i -> i+1 of a clockwise polygon."""
    d = np.roll(polygon, -1, axis=0) - polygon
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return np.stack([d[:, 1], -d[:, 0]], axis=1)


def offset_polygon(polygon: np.ndarray, distance: float) -> np.ndarray:
    """Move every edge of a clockwise polygon inwards by ``distance`` (mitred corners)."""
    n = inward_normals(polygon)
    n_prev = np.roll(n, 1, axis=0)
    scale = distance / (1.0 + np.sum(n * n_prev, axis=1))
    return polygon + (n + n_prev) * scale[:, None]


def min_leg_width(polygon: np.ndarray) -> float:
    """Smallest distance between two parallel, facing edges (the narrowest part of the room)."""
    n = inward_normals(polygon)
    best = np.inf
    for i in range(len(polygon)):
        for j in range(len(polygon)):
            if np.dot(n[i], n[j]) < -0.999:
                gap = float(np.dot(polygon[j] - polygon[i], n[i]))
                # facing edges must overlap along their direction to bound a leg of the room
                d = polygon[(i + 1) % len(polygon)] - polygon[i]
                d = d / np.linalg.norm(d)
                a = sorted([0.0, float(np.dot(polygon[(i + 1) % len(polygon)] - polygon[i], d))])
                b = sorted([
                    float(np.dot(polygon[j] - polygon[i], d)),
                    float(np.dot(polygon[(j + 1) % len(polygon)] - polygon[i], d))
                ])
                if gap > 0 and min(a[1], b[1]) - max(a[0], b[0]) > EPS:
                    best = min(best, gap)
    return best


# ----------------------------------------------------------------------------- room shapes


def sample_room(rng: np.random.Generator, room_cfg: Mapping[str,
                                                            Any]) -> tuple[str, np.ndarray, float]:
    """Sample a room shape, its clockwise floor polygon (min corner at the origin) and height."""
    shapes = list(room_cfg['shapes'])
    probs = np.array([room_cfg['shapes'][s] for s in shapes], dtype=float)
    shape = shapes[int(rng.choice(len(shapes), p=probs / probs.sum()))]
    w = round(float(rng.uniform(*room_cfg['width'])), 2)
    d = round(float(rng.uniform(*room_cfg['depth'])), 2)
    h = round(float(rng.uniform(*room_cfg['height'])), 2)
    if shape == 'box':
        poly = [(0, 0), (0, d), (w, d), (w, 0)]
    elif shape == 'L':
        cw = round(float(rng.uniform(0.35, 0.5)) * w, 2)
        cd = round(float(rng.uniform(0.35, 0.5)) * d, 2)
        poly = [(0, 0), (0, d), (w - cw, d), (w - cw, d - cd), (w, d - cd), (w, 0)]
    else:  # U: a notch in the middle of the far wall
        nw = round(float(rng.uniform(0.3, 0.4)) * w, 2)
        a = round(float(rng.uniform(0.25 * w, 0.75 * w - nw)), 2)
        nd = round(float(rng.uniform(0.3, 0.45)) * d, 2)
        poly = [(0, 0), (0, d), (a, d), (a, d - nd), (a + nw, d - nd), (a + nw, d), (w, d), (w, 0)]
    polygon = np.array(poly, dtype=float)
    if shape != 'box':
        if rng.random() < 0.5:  # mirror x, keep clockwise
            polygon[:, 0] = w - polygon[:, 0]
            polygon = polygon[::-1]
        if rng.random() < 0.5:  # mirror y
            polygon[:, 1] = d - polygon[:, 1]
            polygon = polygon[::-1]
        polygon = np.roll(polygon, -int(np.lexsort((polygon[:, 1], polygon[:, 0]))[0]), axis=0)
    return shape, np.ascontiguousarray(polygon), h


# ----------------------------------------------------------------------------- placement


class _Placer:
    """Keeps the placed objects and answers 'is this box free?'.

    An object's top stays under ``top_limit``, unless the whole object hangs above
    ``overhead_from`` (over the sensor) and under ``ceiling`` (pipes under the ceiling).
    """

    def __init__(self,
                 polygon: np.ndarray,
                 top_limit: float,
                 clearance: float,
                 ceiling: float = -np.inf,
                 overhead_from: float = np.inf):
        self.polygon = polygon
        self.top_limit = top_limit
        self.clearance = clearance
        self.ceiling = ceiling
        self.overhead_from = overhead_from
        self.objects: list[PlacedObject] = []
        self.blockers: list[PlacedObject] = []  # keep-out volumes (door swings), not written
        self.counters: dict[str, int] = {}

    def within(self, region: np.ndarray) -> '_Placer':
        """A placer for the part ``region`` of this one's polygon, sharing its objects."""
        part = _Placer(region, self.top_limit, self.clearance, self.ceiling, self.overhead_from)
        part.objects, part.blockers, part.counters = self.objects, self.blockers, self.counters
        return part

    def is_free(self,
                candidate: PlacedObject,
                ignore: str | None = None,
                clearance: float | None = None) -> bool:
        """Inside the room and its height limits, ``clearance`` (default: the placer's) away
        from every object but ``ignore``."""
        bottom = candidate.center[2] - candidate.size[2] / 2
        top = candidate.center[2] + candidate.size[2] / 2
        overhead = bottom >= self.overhead_from and top <= self.ceiling + EPS
        if top > self.top_limit and not overhead:
            return False
        clearance = self.clearance if clearance is None else clearance
        for other in self.objects + self.blockers:
            if other.instance == ignore:
                continue
            if boxes_intersect(candidate, other, clearance):
                return False
        quad = box_corners_xy(candidate.center, candidate.size, candidate.yaw)
        return quad_inside_polygon(quad, self.polygon)

    def add(self,
            spec: AssetSpec,
            center: np.ndarray,
            yaw: float,
            on: str | None = None) -> PlacedObject:
        self.counters[spec.cls] = self.counters.get(spec.cls, 0) + 1
        obj = PlacedObject(f'{spec.cls}_{self.counters[spec.cls]}', spec, center, yaw, on)
        self.objects.append(obj)
        return obj

    def place_first_free(self,
                         spec: AssetSpec,
                         propose: Callable[[int], tuple[np.ndarray, float]],
                         tries: int,
                         on: str | None = None,
                         clearance: float | None = None) -> PlacedObject | None:
        """Place ``spec`` at the first free pose ``propose(attempt) -> (center, yaw)`` of
        ``tries`` attempts (an object standing ``on`` another may touch it); None if none is."""
        for attempt in range(tries):
            center, yaw = propose(attempt)
            if self.is_free(PlacedObject('', spec, center, yaw), ignore=on, clearance=clearance):
                return self.add(spec, center, yaw, on)
        return None


def _wrap_angle(yaw: float) -> float:
    return float((yaw + np.pi) % (2 * np.pi) - np.pi)


def _pick(rng: np.random.Generator, probs: Mapping[str, float],
          classes: Sequence[str]) -> str | None:
    """Draw one of ``classes`` with their probabilities, or None with the remaining mass."""
    r = rng.random()
    acc = 0.0
    for cls in classes:
        acc += probs[cls]
        if r < acc:
            return cls
    return None


def _fits_on_side(table: AssetSpec, item: AssetSpec, margin: float = 0.03) -> list[int]:
    """Quarter turns (0..3) in which ``item`` fits on one half of the table top."""
    if table.top_size is None or table.top_z is None or table.size[2] > table.top_z + 0.01:
        return []  # no usable top, or parts above the top (a shelf) that an item would hit
    half_w, depth = table.top_size[0] / 2 - margin, table.top_size[1] - 2 * margin
    turns = []
    for k in range(4):
        sx, sy = (item.size[0], item.size[1]) if k % 2 == 0 else (item.size[1], item.size[0])
        if sx <= half_w and sy <= depth:
            turns.append(k)
    return turns


def _turns_for(item: AssetSpec, table: AssetSpec) -> list[int]:
    turns = _fits_on_side(table, item)
    if item.cls == 'yumi':  # the robot faces the front of the table, like its operator
        turns = [k for k in turns if k == 0]
    return turns


def _wall_frame(polygon: np.ndarray,
                wall: int) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """Start, unit direction, length and inward unit normal of edge ``wall`` of ``polygon``."""
    p0, p1 = polygon[wall], polygon[(wall + 1) % len(polygon)]
    length = float(np.linalg.norm(p1 - p0))
    return p0, (p1 - p0) / length, length, inward_normals(polygon)[wall]


def _facing_yaw(normal: np.ndarray) -> float:
    """Yaw of an object whose front (local -y) faces ``normal``."""
    return _wrap_angle(float(np.arctan2(normal[0], -normal[1])))


def _place_wall_item(rng,
                     placer: _Placer,
                     spec: AssetSpec,
                     wall: int,
                     gap_range,
                     tries: int = 12) -> PlacedObject | None:
    p0, direction, length, normal = _wall_frame(placer.polygon, wall)
    width, depth = spec.size[0], spec.size[1]
    if width > length - 0.2:
        return None
    yaw = _facing_yaw(normal)

    def propose(_attempt: int) -> tuple[np.ndarray, float]:
        u = rng.uniform(0.1 + width / 2, length - 0.1 - width / 2)
        gap = rng.uniform(*gap_range)
        xy = p0 + direction * u + normal * (gap + depth / 2)
        return np.array([xy[0], xy[1], spec.size[2] / 2]), yaw

    return placer.place_first_free(spec, propose, tries)


def _place_on_table(rng, placer: _Placer, table: PlacedObject, side: int, item: AssetSpec) -> bool:
    """Put ``item`` on the left (side=-1) or right (side=+1) half of ``table``'s top."""
    turns = _turns_for(item, table.spec)
    if not turns:
        return False
    k = int(rng.choice(turns))
    sx, sy = (item.size[0], item.size[1]) if k % 2 == 0 else (item.size[1], item.size[0])
    top_w, top_d = table.spec.top_size
    slack_x = max(0.0, top_w / 2 - 0.03 - sx) / 2
    slack_y = max(0.0, top_d - 0.06 - sy) / 2
    local = np.array([
        side * top_w / 4 + rng.uniform(-slack_x, slack_x) * 0.8,
        rng.uniform(-slack_y, slack_y) * 0.8
    ])
    xy = table.center[:2] + rotation2d(table.yaw) @ local
    z0 = table.base[2] + table.spec.top_z
    center = np.array([xy[0], xy[1], z0 + item.size[2] / 2])
    yaw = _wrap_angle(table.yaw + k * np.pi / 2)
    placed = placer.place_first_free(item, lambda _attempt: (center, yaw), 1, on=table.instance)
    return placed is not None


def _crate_above(rng, placer: _Placer, support: PlacedObject) -> AssetSpec | None:
    """A crate for the top of ``support`` (as big as a 3D printer on a table), or None when
    less than 25 cm are left under the height limit."""
    room_above = placer.top_limit - (support.base[2] + support.spec.top_z)
    if room_above < 0.25:
        return None
    return sample_clutter(rng, 'crate', room_above, small=support.cls == 'table')


def _place_crate_on_side(rng, placer: _Placer, table: PlacedObject, side: int) -> bool:
    """A closed crate as big as a 3D printer on the free ``side`` of ``table``'s top: a hard
    negative for the printers, which stand on the same tables."""
    crate = _crate_above(rng, placer, table)
    return crate is not None and _place_on_table(rng, placer, table, side, crate)


def _place_openings(rng, placer: _Placer, room_cfg, layout: RoomLayout) -> None:
    polygon = layout.polygon
    lengths = np.linalg.norm(np.roll(polygon, -1, axis=0) - polygon, axis=1)
    normals = inward_normals(polygon)
    per_wall: dict[int, list[tuple[float, float]]] = {}
    n_doors = int(rng.integers(room_cfg['doors'][0], room_cfg['doors'][1] + 1))
    n_windows = int(rng.integers(room_cfg['windows'][0], room_cfg['windows'][1] + 1))
    for kind in ['door'] * n_doors + ['window'] * n_windows:
        for _ in range(10):
            if kind == 'door':
                width = rng.uniform(0.9, 1.3)
                z0, z1 = 0.0, min(rng.uniform(2.0, 2.3), layout.height - 0.3)
            else:
                width = rng.uniform(0.8, 2.0)
                z0 = rng.uniform(0.9, 1.2)
                z1 = z0 + min(rng.uniform(0.8, 1.6), layout.height - z0 - 0.3)
            eligible = np.flatnonzero(lengths >= width + 0.8)
            if len(eligible) == 0:
                break
            wall = int(rng.choice(eligible, p=lengths[eligible] / lengths[eligible].sum()))
            u0 = rng.uniform(0.4, lengths[wall] - 0.4 - width)
            u1 = u0 + width
            if any(u0 < b + 0.3 and a < u1 + 0.3 for a, b in per_wall.get(wall, [])):
                continue
            per_wall.setdefault(wall, []).append((u0, u1))
            layout.openings.append(
                Opening(kind, wall, round(u0, 3), round(u1, 3), round(z0, 3), round(z1, 3)))
            if kind == 'door':  # keep the door's swing free
                direction = (polygon[(wall + 1) % len(polygon)] - polygon[wall]) / lengths[wall]
                xy = polygon[wall] + direction * (u0 + u1) / 2 + normals[wall] * 0.5
                yaw = float(np.arctan2(direction[1], direction[0]))
                spec = AssetSpec('keepout', 'door_swing', 'keepout', {}, (width + 0.2, 1.0, z1))
                placer.blockers.append(
                    PlacedObject(f'door_swing_{len(placer.blockers)}', spec,
                                 np.array([xy[0], xy[1], z1 / 2]), yaw))
            break


CONTACT = 0.0  # clutter may touch what it stands next to, never enter its box


def _place_clutter(rng, placer: _Placer, layout_cfg,
                   free_sides: Sequence[tuple[PlacedObject, int]]) -> None:
    """Crates on ``free_sides`` of tables (``layout.free_side_crate``), then
    ``layout.clutter`` objects of kinds drawn from ``layout.clutter_kinds``; after the
    detection objects so that they never take their place."""
    if layout_cfg['free_side_crate'] > 0:  # no draw at 0: the layouts of earlier versions
        for table, side in free_sides:
            if rng.random() < layout_cfg['free_side_crate']:
                _place_crate_on_side(rng, placer, table, side)
    low, high = layout_cfg['clutter']
    for _ in range(int(rng.integers(low, high + 1))):
        kind = _pick(rng, layout_cfg['clutter_kinds'], CLUTTER_KINDS)
        if kind is None:  # rounding left the probabilities a hair below 1
            continue
        if kind in PRIMITIVE_KINDS:
            _place_primitive(rng, placer, kind, layout_cfg['clutter_size'])
        elif kind in WALL_KINDS:
            spec = sample_clutter(rng, kind, placer.top_limit)
            _place_against_wall(rng, placer, spec, layout_cfg['wall_gap'])
        elif kind == 'pipe':
            _place_pipe_run(rng, placer, layout_cfg['wall_gap'])
        else:
            if kind == 'crate' and rng.random() < 0.5 and _place_crate_on_top(rng, placer):
                continue
            _place_on_floor(rng, placer, sample_clutter(rng, kind, placer.top_limit))


def _place_primitive(rng, placer: _Placer, kind: str, size_range) -> None:
    """A plain box or cylinder anywhere on the floor, keeping the clearance (the light clutter
    of earlier versions, drawn exactly as they did)."""
    spec = sample_primitive(rng, kind, size_range)
    lo_xy, hi_xy = placer.polygon.min(axis=0), placer.polygon.max(axis=0)

    def propose(_attempt: int) -> tuple[np.ndarray, float]:
        xy = rng.uniform(lo_xy, hi_xy)
        return np.array([xy[0], xy[1], spec.size[2] / 2]), float(rng.uniform(-np.pi, np.pi))

    placer.place_first_free(spec, propose, 20)


def _wall_lengths(polygon: np.ndarray) -> np.ndarray:
    return np.linalg.norm(np.roll(polygon, -1, axis=0) - polygon, axis=1)


def _draw_wall(rng, lengths: np.ndarray, min_length: float) -> int | None:
    """A wall at least ``min_length`` long, drawn with probability proportional to length."""
    walls = np.flatnonzero(lengths >= min_length)
    if len(walls) == 0:
        return None
    return int(rng.choice(walls, p=lengths[walls] / lengths[walls].sum()))


def _spans_at_wall(placer: _Placer, p0: np.ndarray, direction: np.ndarray,
                   normal: np.ndarray) -> list[tuple[float, float]]:
    """Spans (u0, u1) along a wall of the floor objects standing within 0.3 m of it."""
    spans = []
    for obj in placer.objects:
        if obj.on is not None:
            continue
        quad = box_corners_xy(obj.center, obj.size, obj.yaw)
        if ((quad - p0) @ normal).min() <= 0.3:
            along = (quad - p0) @ direction
            spans.append((float(along.min()), float(along.max())))
    return spans


def _place_against_wall(rng,
                        placer: _Placer,
                        spec: AssetSpec,
                        gap_range,
                        tries: int = 12) -> PlacedObject | None:
    """Back to a wall (a gap in ``gap_range``), often side by side with what stands there."""
    width, depth = spec.size[0], spec.size[1]
    lengths = _wall_lengths(placer.polygon)
    if _draw_wall(rng, lengths, width + 0.2) is None:
        return None
    spans_of: dict[int, list[tuple[float, float]]] = {}

    def propose(_attempt: int) -> tuple[np.ndarray, float]:
        wall = _draw_wall(rng, lengths, width + 0.2)
        p0, direction, length, normal = _wall_frame(placer.polygon, wall)
        low, high = 0.1 + width / 2, length - 0.1 - width / 2
        u = rng.uniform(low, high)
        if wall not in spans_of:
            spans_of[wall] = _spans_at_wall(placer, p0, direction, normal)
        spans = spans_of[wall]
        if spans and rng.random() < 0.6:
            u0, u1 = spans[int(rng.integers(len(spans)))]
            gap = rng.uniform(0.0, 0.02)
            u = min(
                max(u1 + gap + width / 2 if rng.random() < 0.5 else u0 - gap - width / 2, low),
                high)
        xy = p0 + direction * u + normal * (rng.uniform(*gap_range) + depth / 2)
        return np.array([xy[0], xy[1], spec.size[2] / 2]), _facing_yaw(normal)

    return placer.place_first_free(spec, propose, tries, clearance=CONTACT)


def _place_pipe_run(rng, placer: _Placer, gap_range, tries: int = 12) -> PlacedObject | None:
    """A pipe run along a wall: on the wall (low, or high over the sensor) or hung from the
    ceiling 0.1-1.5 m in front of it."""
    wall = _draw_wall(rng, _wall_lengths(placer.polygon), 1.5)
    if wall is None:
        return None
    p0, direction, length, normal = _wall_frame(placer.polygon, wall)
    overhead = placer.ceiling - placer.overhead_from  # free height over the sensor
    mount = 'ceiling' if overhead > 0.3 and rng.random() < 0.5 else 'wall'
    run = rng.uniform(0.4, 1.0) * (length - 0.2)
    spec = sample_pipe_run(rng, run, mount, overhead)
    width, depth, height = spec.size

    def propose(_attempt: int) -> tuple[np.ndarray, float]:
        u = rng.uniform(0.1 + width / 2, length - 0.1 - width / 2)
        if mount == 'ceiling':
            offset, z = rng.uniform(0.1, 1.5), placer.ceiling - height / 2
        else:
            offset = rng.uniform(*gap_range)
            high = overhead > height + 0.02 and rng.random() < 0.5
            low, top = ((placer.overhead_from, placer.ceiling - 0.02) if high else
                        (0.1, placer.top_limit))
            z = rng.uniform(low, max(low, top - height)) + height / 2
        xy = p0 + direction * u + normal * (offset + depth / 2)
        return np.array([xy[0], xy[1], z]), _facing_yaw(normal)

    return placer.place_first_free(spec, propose, tries, clearance=CONTACT)


def _floor_objects(placer: _Placer) -> list[PlacedObject]:
    """Objects standing on the floor of ``placer``'s region."""
    objects = [o for o in placer.objects if o.on is None]
    if not objects:
        return []
    inside = points_in_polygon(np.array([o.center[:2] for o in objects]), placer.polygon)
    return [o for o, keep in zip(objects, inside) if keep]


def _beside(rng, anchor: PlacedObject, spec: AssetSpec) -> tuple[np.ndarray, float]:
    """A floor pose for ``spec`` against a random side of ``anchor``'s box, 0-3 cm away, turned
    like the anchor or a quarter turn more."""
    turn = int(rng.integers(2))
    half = np.asarray(spec.size[:2], dtype=float) / 2
    if turn:
        half = half[::-1]
    axis = int(rng.integers(2))
    sign = 1.0 if rng.random() < 0.5 else -1.0
    local = np.zeros(2)
    local[axis] = sign * (anchor.size[axis] / 2 + half[axis] + rng.uniform(0.0, 0.03))
    local[1 - axis] = rng.uniform(-0.8, 0.8) * (anchor.size[1 - axis] / 2 + half[1 - axis])
    xy = anchor.center[:2] + rotation2d(anchor.yaw) @ local
    return np.array([xy[0], xy[1], spec.size[2] / 2]), _wrap_angle(anchor.yaw + turn * np.pi / 2)


def _place_on_floor(rng, placer: _Placer, spec: AssetSpec, tries: int = 16) -> None:
    """Every other try against an object on the floor (a detection object 3 times in 4), else
    anywhere with a random yaw."""
    standing = _floor_objects(placer)
    detection = [o for o in standing if o.cls != 'clutter']
    lo_xy, hi_xy = placer.polygon.min(axis=0), placer.polygon.max(axis=0)

    def propose(attempt: int) -> tuple[np.ndarray, float]:
        if standing and attempt % 2 == 0:
            pool = detection if detection and rng.random() < 0.75 else standing
            return _beside(rng, pool[int(rng.integers(len(pool)))], spec)
        xy = rng.uniform(lo_xy, hi_xy)
        return np.array([xy[0], xy[1], spec.size[2] / 2]), float(rng.uniform(-np.pi, np.pi))

    placer.place_first_free(spec, propose, tries, clearance=CONTACT)


def _place_crate_on_top(rng, placer: _Placer, tries: int = 8) -> bool:
    """A crate on an empty pallet or on a free part of a table top (there as big as a 3D
    printer); False when none takes it."""
    supports = [
        o for o in _floor_objects(placer)
        if o.cls in ('table',
                     'clutter') and o.spec.top_z is not None and o.size[2] <= o.spec.top_z + 0.01
    ]
    if not supports:
        return False
    support = supports[int(rng.integers(len(supports)))]
    spec = _crate_above(rng, placer, support)
    if spec is None:
        return False
    top_z = support.base[2] + support.spec.top_z
    top_w, top_d = support.spec.top_size
    turns = [
        k for k in range(4)
        if spec.size[k % 2] <= top_w - 0.02 and spec.size[1 - k % 2] <= top_d - 0.02
    ]
    if not turns:
        return False

    def propose(_attempt: int) -> tuple[np.ndarray, float]:
        k = turns[int(rng.integers(len(turns)))]
        slack = np.array([top_w - spec.size[k % 2], top_d - spec.size[1 - k % 2]]) / 2 - 0.01
        xy = support.center[:2] + rotation2d(support.yaw) @ rng.uniform(-slack, slack)
        return (np.array([xy[0], xy[1],
                          top_z + spec.size[2] / 2]), _wrap_angle(support.yaw + k * np.pi / 2))

    placed = placer.place_first_free(spec, propose, tries, on=support.instance, clearance=CONTACT)
    return placed is not None


def _furnish(rng: np.random.Generator, placer: '_Placer', catalog: Catalog,
             probs: Mapping[str, float], layout_cfg: Mapping[str, Any]) -> None:
    """Place wall items, chairs and clutter in ``placer.polygon`` (a room, or a bay of a hall)."""
    # tables and sofas share the wall slots: the longest walls, at most 4
    polygon = placer.polygon
    lengths = np.linalg.norm(np.roll(polygon, -1, axis=0) - polygon, axis=1)
    tie_break = rng.random(len(lengths))
    walls = [int(i) for i in np.lexsort((tie_break, -np.round(lengths, 3)))
             if lengths[i] >= 1.8][:layout_cfg['wall_slots']]
    free_sides: list[tuple[PlacedObject, int]] = []  # table sides left without an item
    for wall in walls:
        cls = _pick(rng, probs, ('table', 'sofa'))
        if cls is None or not catalog.get(cls):
            continue
        if cls == 'sofa':
            spec = catalog['sofa'][int(rng.integers(len(catalog['sofa'])))]
            _place_wall_item(rng, placer, spec, wall, layout_cfg['wall_gap'])
            continue
        # decide what goes on the table first, then pick a table whose top holds it
        items = []
        for side in (-1, 1):
            item_cls = _pick(rng, probs, ('yumi', '3dprinter'))
            pool = [
                s for s in catalog.get(item_cls, ()) if any(
                    _turns_for(s, t) for t in catalog['table'])
            ]
            if pool:
                items.append((side, pool[int(rng.integers(len(pool)))]))
        tables = list(catalog['table'])
        while True:
            fitting = [t for t in tables if all(_turns_for(item, t) for _, item in items)]
            if fitting or not items:
                break
            items.pop(int(rng.integers(len(items))))  # nothing holds both: drop one
        if not fitting:
            fitting = tables
        table_spec = fitting[int(rng.integers(len(fitting)))]
        table = _place_wall_item(rng, placer, table_spec, wall, layout_cfg['wall_gap'])
        if table is None:
            continue
        taken = {side for side, item in items if _place_on_table(rng, placer, table, side, item)}
        free_sides += [(table, side) for side in (-1, 1) if side not in taken]

    # chairs: 4 evenly spaced positions on the inner boundary, random phase and rotations
    if catalog.get('chair') and layout_cfg['chair_positions'] > 0:
        margin = min(float(layout_cfg['chair_margin']), 0.3 * min_leg_width(polygon))
        inner = offset_polygon(polygon, margin)
        edges = np.roll(inner, -1, axis=0) - inner
        cumulative = np.concatenate([[0.0], np.cumsum(np.linalg.norm(edges, axis=1))])
        perimeter = cumulative[-1]
        phase = rng.random()
        n_pos = layout_cfg['chair_positions']
        for k in range(n_pos):
            if rng.random() >= probs['chair']:
                continue
            spec = catalog['chair'][int(rng.integers(len(catalog['chair'])))]

            def propose(attempt: int) -> tuple[np.ndarray, float]:
                shift = 0.0 if attempt == 0 else rng.uniform(-0.15, 0.15)
                s = ((phase + k / n_pos + shift) % 1.0) * perimeter
                i = min(int(np.searchsorted(cumulative, s, side='right')) - 1, len(inner) - 1)
                t = (s - cumulative[i]) / max(cumulative[i + 1] - cumulative[i], EPS)
                xy = inner[i] + t * edges[i]
                yaw = float(rng.uniform(-np.pi, np.pi))
                return np.array([xy[0], xy[1], spec.size[2] / 2]), yaw

            placer.place_first_free(spec, propose, 8)

    _place_clutter(rng, placer, layout_cfg, free_sides)


def _overhead_from(config: Mapping[str, Any], height: float) -> float:
    """Lowest z of an object hung over the sensor path (10 cm above it)."""
    return float(config['scanner']['sensor_height']) * height + 0.1


def generate_layout(rng: np.random.Generator, catalog: Catalog,
                    config: Mapping[str, Any]) -> RoomLayout:
    """Sample one room (or a hall, when ``config`` has a ``hall`` section) and its objects
    following the placement rules (see module docstring)."""
    if 'hall' in config:
        return generate_hall_layout(rng, catalog, config)
    room_cfg, probs, layout_cfg = config['room'], config['probabilities'], config['layout']
    kind = None  # without ``room_kinds`` nothing is drawn: the factory rooms of earlier versions
    if 'room_kinds' in config:
        kind = _pick(rng, config['room_kinds'], ROOM_KINDS) or 'factory'
    if kind not in (None, 'factory'):
        from generator.room_kinds import kind_room_config  # its rules use this module's placer
        room_cfg = kind_room_config(room_cfg, kind)
    shape, polygon, height = sample_room(rng, room_cfg)
    layout = RoomLayout(shape, polygon, height, kind=kind)
    # objects stay below the sensor (and the ceiling), so the sensor path never runs through one
    top_limit = min(height - 0.05, float(config['scanner']['sensor_height']) * height - 0.1)
    placer = _Placer(polygon, top_limit, float(layout_cfg['clearance']), height,
                     _overhead_from(config, height))
    _place_openings(rng, placer, room_cfg, layout)

    if kind in (None, 'factory'):
        _furnish(rng, placer, catalog, probs, layout_cfg)
    else:
        from generator.room_kinds import furnish_kind
        furnish_kind(rng, placer, catalog, layout, kind)
    layout.objects = placer.objects
    return layout


def _bay_edges(length: float, bay_range: Sequence[float], rng: np.random.Generator) -> np.ndarray:
    """Bay boundaries along one side of a hall: equal bays, their side in ``bay_range`` when a
    whole number of such bays fits (the count is drawn among those), else as close as fits."""
    fewest = max(1, math.ceil(length / bay_range[1] - EPS))
    most = max(fewest, math.floor(length / bay_range[0] + EPS))
    count = int(rng.integers(fewest, most + 1))
    return np.round(np.linspace(0.0, length, count + 1), 3)


def _hall_partitions(xs: np.ndarray, ys: np.ndarray, rng: np.random.Generator,
                     hall_cfg: Mapping[str, Any]) -> list[Partition]:
    """Partition walls on the boundaries between bays, each with a passage."""
    segments = [(np.array([x, y0]), np.array([x, y1])) for x in xs[1:-1]
                for y0, y1 in zip(ys[:-1], ys[1:])]
    segments += [(np.array([x0, y]), np.array([x1, y])) for y in ys[1:-1]
                 for x0, x1 in zip(xs[:-1], xs[1:])]
    partitions = []
    passage = float(hall_cfg['passage'])
    for start, end in segments:
        if rng.random() >= hall_cfg['partitions']:
            continue
        length = float(np.linalg.norm(end - start))
        u0 = round(float(rng.uniform(0.5, length - 0.5 - passage)), 3)
        partitions.append(Partition(start, end, u0, round(u0 + passage, 3)))
    return partitions


def generate_hall_layout(rng: np.random.Generator, catalog: Catalog,
                         config: Mapping[str, Any]) -> RoomLayout:
    """A factory hall: a rectangle cut into a grid of bays, each furnished by the room rules
    (wall slots on the bay's sides, chairs on its inner boundary, clutter), optional partition
    walls with a passage between bays, and doors and windows in the outer walls."""
    hall_cfg, probs, layout_cfg = config['hall'], config['probabilities'], config['layout']
    width = round(float(rng.uniform(*hall_cfg['width'])), 2)
    depth = round(float(rng.uniform(*hall_cfg['depth'])), 2)
    height = round(float(rng.uniform(*hall_cfg['height'])), 2)
    polygon = np.array([(0.0, 0.0), (0.0, depth), (width, depth), (width, 0.0)])
    xs = _bay_edges(width, hall_cfg['bay'], rng)
    ys = _bay_edges(depth, hall_cfg['bay'], rng)
    bays = [
        np.array([[x0, y0], [x0, y1], [x1, y1], [x1, y0]]) for x0, x1 in zip(xs[:-1], xs[1:])
        for y0, y1 in zip(ys[:-1], ys[1:])
    ]
    layout = RoomLayout(
        'hall', polygon, height, bays=bays, partitions=_hall_partitions(xs, ys, rng, hall_cfg))
    top_limit = min(height - 0.05, float(config['scanner']['sensor_height']) * height - 0.1)
    placer = _Placer(polygon, top_limit, float(layout_cfg['clearance']), height,
                     _overhead_from(config, height))
    _place_openings(rng, placer, hall_cfg, layout)
    for bay in bays:
        _furnish(rng, placer.within(bay), catalog, probs, layout_cfg)
    layout.objects = placer.objects
    return layout


def layout_meta(layout: RoomLayout) -> dict[str, Any]:
    """The ``room`` and ``objects`` parts of ``meta.json``.

    ``room.openings`` (beyond the contract's polygon and height) lists doors and windows: their
    annotation name, the wall (polygon edge i -> i+1), the span ``u`` along it and ``z``.
    """
    counters: dict[str, int] = {}
    names = []
    for opening in layout.openings:
        counters[opening.kind] = counters.get(opening.kind, 0) + 1
        names.append(f'{opening.kind}_{counters[opening.kind]}')
    room = {
        'polygon': [[round(float(x), 6), round(float(y), 6)] for x, y in layout.polygon],
        'height':
        round(float(layout.height), 6),
        'shape':
        layout.shape,
        'openings': [{
            'instance': name,
            'kind': o.kind,
            'wall': o.wall,
            'u': [o.u0, o.u1],
            'z': [o.z0, o.z1]
        } for name, o in zip(names, layout.openings)]
    }
    if layout.kind is not None:
        room['kind'] = layout.kind
    if layout.shape == 'hall':
        room['bays'] = [[[float(x), float(y)] for x, y in bay] for bay in layout.bays]
        room['partitions'] = [{
            'instance': name,
            'start': [float(v) for v in p.start],
            'end': [float(v) for v in p.end],
            'passage': [p.u0, p.u1]
        } for name, p in zip(partition_names(layout), layout.partitions)]
    objects = [{
        'instance': o.instance,
        'class': o.cls,
        'asset': o.spec.asset,
        'params': _jsonable(o.spec.params),
        'box': o.box_dict(),
        'on': o.on
    } for o in layout.objects]
    return {'room': room, 'objects': objects}


def partition_names(layout: RoomLayout) -> list[str]:
    """Annotation names of a hall's partitions: walls numbered after the outer walls."""
    return [f'wall_{len(layout.polygon) + k}' for k in range(1, len(layout.partitions) + 1)]


def _jsonable(value: Any) -> Any:
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_jsonable(v) for v in value]
    if isinstance(value, (np.floating, float)):
        return round(float(value), 6)
    if isinstance(value, np.integer):
        return int(value)
    return value
