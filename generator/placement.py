"""What a layout is made of and the placer that keeps it free of intersections.

A layout (``RoomLayout``) is a floor polygon, a height, door and window openings and placed
objects (``PlacedObject``: an asset and its oriented box); a hall adds bays and partition walls.
The ``Placer`` holds the objects placed so far and accepts a new one only inside the polygon,
under the height limit and clear of every other box (oriented-box tests). The furnishing rules
(generator/furnish.py), the room kinds (generator/room_kinds.py), rooms (generator/layout.py)
and halls (generator/hall_layout.py) all place through it.

Frames: metres, z up, yaw in radians counter-clockwise from +x. An object's local frame has xy
centred on its bounding box, z = 0 at its lowest point, and its front towards local -y.
"""
import math
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from generator.asset_spec import AssetSpec
from synthdet.classes import GENERATED_CLASSES
from synthdet.geometry import box_corners_xy, edges_cross, points_in_polygon, signed_area

EPS = 1e-9
CONTACT = 0.0  # clutter may touch what it stands next to, never enter its box


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


# ----------------------------------------------------------------------------- geometry


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


class Placer:
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

    def within(self, region: np.ndarray) -> 'Placer':
        """A placer for the part ``region`` of this one's polygon, sharing its objects."""
        part = Placer(region, self.top_limit, self.clearance, self.ceiling, self.overhead_from)
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


def room_placer(polygon: np.ndarray, height: float, config: Mapping[str, Any]) -> Placer:
    """The placer of a room or hall ``height`` high: objects stay below the sensor (and the
    ceiling), so the sensor path never runs through one, unless they hang 10 cm or more above
    it (pipes under the ceiling)."""
    sensor_z = float(config['scanner']['sensor_height']) * height
    return Placer(polygon, min(height - 0.05, sensor_z - 0.1),
                  float(config['layout']['clearance']), height, sensor_z + 0.1)


def wrap_angle(yaw: float) -> float:
    """``yaw`` in [-pi, pi)."""
    return float((yaw + np.pi) % (2 * np.pi) - np.pi)


def pick(rng: np.random.Generator, probs: Mapping[str, float],
         classes: Sequence[str]) -> str | None:
    """Draw one of ``classes`` with their probabilities, or None with the remaining mass."""
    r = rng.random()
    acc = 0.0
    for cls in classes:
        acc += probs[cls]
        if r < acc:
            return cls
    return None


def wall_frame(polygon: np.ndarray, wall: int) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """Start, unit direction, length and inward unit normal of edge ``wall`` of ``polygon``."""
    p0, p1 = polygon[wall], polygon[(wall + 1) % len(polygon)]
    length = float(np.linalg.norm(p1 - p0))
    return p0, (p1 - p0) / length, length, inward_normals(polygon)[wall]


def facing_yaw(normal: np.ndarray) -> float:
    """Yaw of an object whose front (local -y) faces ``normal``."""
    return wrap_angle(float(np.arctan2(normal[0], -normal[1])))


def wall_lengths(polygon: np.ndarray) -> np.ndarray:
    """Length of each edge i -> i+1 of ``polygon``."""
    return np.linalg.norm(np.roll(polygon, -1, axis=0) - polygon, axis=1)
