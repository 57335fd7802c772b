"""Furniture rules of the room kinds beyond the factory room, in plain numpy.

A room's kind is drawn from the configuration's ``room_kinds`` (generator/config.py); a factory
room follows the paper's rules (generator/furnish.py), the other kinds follow their own and never
hold a YuMi or a 3D printer:

- ``office``: desks against the walls (and at times two back to back in the middle), each with a
  chair in front of it and monitors, a keyboard, a PC tower, books or a lamp on it; bookshelves,
  cabinets, bins, plants, now and then a sofa;
- ``meeting``: a meeting table in the middle of the room with chairs around it, a TV on a stand,
  cabinets and spare chairs along the walls;
- ``living``: a sofa (or a corner sofa) against a wall with a coffee table in front of it and
  end tables beside it, at times a sofa facing it across the table, armchairs, a TV on its
  stand across the room, shelves, lamps, plants, at times a dining table;
- ``bedroom``: a bed with its head against a wall, night stands with lamps, a wardrobe, at times
  a desk with a chair;
- ``lab``: benches along the walls with monitors, PC towers and boxes on them, stools and swivel
  chairs, shelves and cabinets.

Every kind gets radiators under its windows, curtains, doors leaning in their frames, bags, boxes
and bins. The placement checks of the layout apply: nothing intersects, detection objects keep
``layout.clearance`` among themselves, clutter may touch what it stands next to.
"""
import math
from typing import Any, Mapping, Sequence

import numpy as np

from generator.clutter import sample_clutter
from generator.household import FURNITURE_KINDS, sample_household
from generator.asset_spec import AssetSpec, Catalog
from generator.furnish import place_against_wall, place_on_floor
from generator.placement import (CONTACT, PlacedObject, Placer, RoomLayout, facing_yaw, wall_frame,
                                 wall_lengths, wrap_angle)
from synthdet.geometry import rotation2d

# floor size and height of each kind's rooms (metres); real offices, meeting rooms, living rooms
# and bedrooms are smaller and lower than the factory rooms (reconstructed real rooms measure
# 3-7.6 m a side)
KIND_ROOMS: dict[str, dict[str, Any]] = {
    'office': {'width': [3.5, 8.0], 'depth': [3.0, 7.0]},
    'meeting': {'width': [4.0, 8.0], 'depth': [3.5, 6.5]},
    'living': {'width': [4.0, 8.0], 'depth': [3.5, 7.5]},
    'bedroom': {'width': [3.0, 5.0], 'depth': [3.0, 4.5]},
    'lab': {'width': [5.0, 9.0], 'depth': [4.5, 8.0]},
}
KIND_HEIGHT = [2.6, 3.2]
KIND_SHAPES = {'box': 0.85, 'L': 0.15, 'U': 0.0}

# library variants by use (the asset name is '<class>/<variant>')
DESK_TABLES = ('legs', 'pedestal', 'panel', 'cleg', 'standing', 'folding', 'trestle')
MEETING_TABLES = ('legs', 'pedestal', 'panel', 'trestle', 'round', 'folding', 'cleg')
DINING_TABLES = ('legs', 'pedestal', 'round', 'trestle')
LAB_TABLES = ('workbench', 'steelbench', 'legs', 'standing', 'trestle', 'panel')
OFFICE_CHAIRS = ('pedestal', )
GUEST_CHAIRS = ('fourleg', 'cantilever', 'stacking', 'sled')
LAB_CHAIRS = ('stool', 'pedestal')
LIVING_SOFAS = ('1seat', '2seat', '3seat', 'chaise', 'modular')


def kind_room_config(room_cfg: Mapping[str, Any], kind: str) -> dict[str, Any]:
    """The room section for a room of ``kind``: its size and shapes, the openings of
    ``room_cfg``."""
    return {**room_cfg, **KIND_ROOMS[kind], 'height': KIND_HEIGHT, 'shapes': KIND_SHAPES}


def _variant(spec: AssetSpec) -> str:
    return spec.asset.split('/', 1)[-1]


def _choose(rng: np.random.Generator, catalog: Catalog, cls: str,
            variants: Sequence[str] = ()) -> AssetSpec | None:
    """A library instance of ``cls``, of one of ``variants`` when the library has any."""
    specs = list(catalog.get(cls, ()))
    preferred = [s for s in specs if _variant(s) in variants]
    pool = preferred or specs
    return pool[int(rng.integers(len(pool)))] if pool else None


def _walls_by_length(rng, polygon: np.ndarray, min_length: float) -> list[int]:
    """Walls at least ``min_length`` long, longest first (ties in random order)."""
    lengths = wall_lengths(polygon)
    order = np.lexsort((rng.random(len(lengths)), -np.round(lengths, 3)))
    return [int(i) for i in order if lengths[i] >= min_length]


def _at_wall(rng,
             placer: Placer,
             spec: AssetSpec | None,
             walls: Sequence[int],
             gap: Sequence[float] = (0.0, 0.08),
             clearance: float | None = None,
             tries: int = 16,
             u_center: float | None = None) -> PlacedObject | None:
    """``spec`` with its back to one of ``walls`` (drawn per try), facing into the room; at
    ``u_center`` along the wall (metres from its start) when given. None places nothing."""
    if spec is None:
        return None
    lengths = wall_lengths(placer.polygon)
    usable = [w for w in walls if lengths[w] >= spec.size[0] + 0.2]
    if not usable:
        return None

    def propose(attempt: int) -> tuple[np.ndarray, float]:
        wall = usable[attempt % len(usable)] if u_center is None else usable[0]
        p0, direction, length, normal = wall_frame(placer.polygon, wall)
        low, high = 0.1 + spec.size[0] / 2, length - 0.1 - spec.size[0] / 2
        u = rng.uniform(low, high) if u_center is None else min(max(u_center, low), high)
        xy = p0 + direction * u + normal * (rng.uniform(*gap) + spec.size[1] / 2)
        return np.array([xy[0], xy[1], spec.size[2] / 2]), facing_yaw(normal)

    return placer.place_first_free(spec, propose, tries, clearance=clearance)


def _local_pose(anchor: PlacedObject, local_xy: Sequence[float], spec: AssetSpec,
                turn: float, z0: float = 0.0) -> tuple[np.ndarray, float]:
    """A pose at ``local_xy`` in ``anchor``'s frame, turned by ``turn`` from its yaw, standing
    at height ``z0``."""
    xy = anchor.center[:2] + rotation2d(anchor.yaw) @ np.asarray(local_xy, dtype=float)
    return np.array([xy[0], xy[1], z0 + spec.size[2] / 2]), wrap_angle(anchor.yaw + turn)


def _on_top(rng, placer: Placer, support: PlacedObject, spec: AssetSpec,
            where: str = 'any', tries: int = 6) -> PlacedObject | None:
    """``spec`` on ``support``'s free top, facing the support's front; ``where``: at the back,
    the front or anywhere on the top."""
    top_z, top_size = support.spec.top_z, support.spec.top_size
    if top_z is None or top_size is None or support.size[2] > top_z + 0.01:
        return None  # no usable top, or parts above it
    z0 = support.base[2] + top_z

    def slack(turn: float) -> np.ndarray:
        """How far the centre may move on the top with the item turned by ``turn``, 2 cm from
        the edges (nothing overhangs)."""
        c, s = abs(math.cos(turn)), abs(math.sin(turn))
        width, depth = spec.size[0], spec.size[1]
        extent = np.array([c * width + s * depth, s * width + c * depth])
        return (np.asarray(top_size) - extent) / 2 - 0.02

    if (slack(0.0) < 0).any():
        return None

    def propose(_attempt: int) -> tuple[np.ndarray, float]:
        turn = float(rng.normal(0.0, 0.1))
        free = slack(turn)
        if (free < 0).any():
            turn, free = 0.0, slack(0.0)
        x = rng.uniform(-free[0], free[0])
        y = free[1] if where == 'back' else -free[1] if where == 'front' else rng.uniform(
            -free[1], free[1])
        return _local_pose(support, (x, y), spec, turn, z0)

    return placer.place_first_free(spec, propose, tries, on=support.instance, clearance=CONTACT)


def _chair_at(rng, placer: Placer, chair: AssetSpec | None, target: PlacedObject,
              side: Sequence[float],
              along: float = 0.0, gap: Sequence[float] = (0.08, 0.35),
              tries: int = 6) -> PlacedObject | None:
    """``chair`` facing ``target`` from its local ``side`` (a unit axis, e.g. (0, -1): in front),
    ``along`` metres off the middle of that side. None places nothing."""
    if chair is None:
        return None
    side = np.asarray(side, dtype=float)
    reach = abs(side[0]) * target.size[0] / 2 + abs(side[1]) * target.size[1] / 2
    tangent = np.array([-side[1], side[0]])
    facing = float(np.arctan2(-side[0], side[1]))  # the chair's front (-y) towards the target

    def propose(attempt: int) -> tuple[np.ndarray, float]:
        distance = reach + rng.uniform(*gap) + chair.size[1] / 2
        shift = along + (0.0 if attempt == 0 else rng.uniform(-0.15, 0.15))
        turn = facing + float(rng.normal(0.0, 0.25))
        return _local_pose(target, side * distance + tangent * shift, chair, turn)

    return placer.place_first_free(chair, propose, tries)


def _next_to(rng,
             placer: Placer,
             anchor: PlacedObject,
             spec: AssetSpec | None,
             side: int,
             gap: Sequence[float] = (0.0, 0.08),
             clearance: float | None = CONTACT,
             tries: int = 4) -> PlacedObject | None:
    """``spec`` beside ``anchor`` on its local ``side`` (-1: left, +1: right), ``gap`` apart,
    backs aligned (a night stand at a bed, a PC tower at a desk, a side table at a sofa). None
    places nothing."""
    if spec is None:
        return None

    def propose(_attempt: int) -> tuple[np.ndarray, float]:
        x = side * (anchor.size[0] / 2 + spec.size[0] / 2 + rng.uniform(*gap))
        y = anchor.size[1] / 2 - spec.size[1] / 2 - rng.uniform(0.0, 0.05)
        return _local_pose(anchor, (x, y), spec, 0.0)

    return placer.place_first_free(spec, propose, tries, clearance=clearance)


def _household(rng, placer: Placer, kind: str) -> AssetSpec:
    return sample_household(rng, kind, placer.top_limit)


def _furniture(rng, placer: Placer, catalog: Catalog, kind: str) -> AssetSpec | None:
    """A household furniture object of ``kind``, or None when the library lacks its class (a
    user library without tables gets no desks either)."""
    if not catalog.get(FURNITURE_KINDS[kind]):
        return None
    return _household(rng, placer, kind)


def _desk_items(rng, placer: Placer, desk: PlacedObject, monitors: float = 0.85) -> None:
    """Monitors at the back, a keyboard at the front and a few small things on a desk."""
    if rng.random() < monitors:
        for _ in range(1 + int(rng.random() < 0.3)):
            _on_top(rng, placer, desk, _household(rng, placer, 'monitor'), 'back')
    if rng.random() < 0.7:
        _on_top(rng, placer, desk, _household(rng, placer, 'keyboard'), 'front')
    if rng.random() < 0.5:
        tower = _household(rng, placer, 'pc_tower')
        if rng.random() < 0.4:
            _on_top(rng, placer, desk, tower)
        else:
            _next_to(rng, placer, desk, tower, 1 if rng.random() < 0.5 else -1)
    for _ in range(int(rng.integers(0, 4))):
        kind = ('books', 'lamp', 'plant', 'storage_box', 'bag')[int(rng.integers(5))]
        _on_top(rng, placer, desk, _household(rng, placer, kind))


def _window_spans(layout: RoomLayout) -> list[tuple[int, float, float]]:
    return [(o.wall, o.u0, o.u1) for o in layout.openings if o.kind == 'window']


def _room_extras(rng, placer: Placer, catalog: Catalog, layout: RoomLayout,
                 walls: Sequence[int],
                 floor_kinds: Mapping[str, float], wall_kinds: Mapping[str, float],
                 count: Sequence[int]) -> None:
    """Radiators under windows, curtains beside them, then ``count`` (inclusive range) objects:
    against a wall for ``wall_kinds``, on the floor for ``floor_kinds`` (relative weights)."""
    for wall, u0, u1 in _window_spans(layout):
        if rng.random() < 0.6:
            radiator = _household(rng, placer, 'radiator')
            _at_wall(rng, placer, radiator, [wall], (0.03, 0.08), CONTACT, 4, (u0 + u1) / 2)
        if rng.random() < 0.4:
            curtain = _household(rng, placer, 'curtain')
            edge = u0 if rng.random() < 0.5 else u1
            _at_wall(rng, placer, curtain, [wall], (0.05, 0.12), CONTACT, 4, edge)
    if rng.random() < 0.3:
        _at_wall(rng, placer, _household(rng, placer, 'door'), walls, (0.001, 0.01), CONTACT)
    kinds = list(floor_kinds) + list(wall_kinds)
    weights = np.array([floor_kinds.get(k, 0.0) + wall_kinds.get(k, 0.0) for k in kinds])
    for _ in range(int(rng.integers(count[0], count[1] + 1))):
        kind = kinds[int(rng.choice(len(kinds), p=weights / weights.sum()))]
        if kind in ('cabinet', 'shelf'):  # the factory's cabinets and shelving
            spec = sample_clutter(rng, kind, placer.top_limit)
        elif kind in FURNITURE_KINDS:
            spec = _furniture(rng, placer, catalog, kind)
        else:
            spec = _household(rng, placer, kind)
        if spec is None or spec.cls != 'clutter':  # furniture keeps the clearance
            _at_wall(rng, placer, spec, walls, (0.05, 0.4))
        elif kind in wall_kinds:
            place_against_wall(rng, placer, spec, (0.0, 0.05))
        else:
            place_on_floor(rng, placer, spec)


def _spare_chairs(rng, placer: Placer, catalog: Catalog, walls: Sequence[int], count: int,
                  variants: Sequence[str]) -> None:
    """Chairs along the walls, facing into the room."""
    for _ in range(count):
        chair = _choose(rng, catalog, 'chair', variants)
        if chair is not None:
            _at_wall(rng, placer, chair, walls, (0.05, 0.3), tries=8)


def _office_desk(rng, placer: Placer, catalog: Catalog) -> AssetSpec | None:
    """A household desk or a library desk, half and half."""
    if rng.random() < 0.5:
        return _furniture(rng, placer, catalog, 'desk')
    return _choose(rng, catalog, 'table', DESK_TABLES)


def _workplace(rng, placer: Placer, catalog: Catalog, desk: PlacedObject | None) -> None:
    """A chair in front of ``desk`` (a swivel chair 3 times in 4) and things on its top."""
    if desk is None:
        return
    if rng.random() < 0.9:
        chair = _choose(rng, catalog, 'chair',
                        OFFICE_CHAIRS if rng.random() < 0.75 else GUEST_CHAIRS)
        _chair_at(rng, placer, chair, desk, (0.0, -1.0), rng.uniform(-0.2, 0.2))
    _desk_items(rng, placer, desk)


def _desk_island(rng, placer: Placer, catalog: Catalog) -> None:
    """Two desks back to back in the middle of an open-plan office."""
    spec = _office_desk(rng, placer, catalog)
    first = spec and _central_table(rng, placer, spec)
    if first is None:
        return
    _workplace(rng, placer, catalog, first)
    other = _office_desk(rng, placer, catalog)
    if other is None:
        return

    def propose(_attempt: int) -> tuple[np.ndarray, float]:
        y = first.size[1] / 2 + rng.uniform(0.06, 0.12) + other.size[1] / 2
        return _local_pose(first, (rng.uniform(-0.1, 0.1), y), other, np.pi)

    _workplace(rng, placer, catalog, placer.place_first_free(other, propose, 4))


def _furnish_office(rng, placer, catalog, layout, walls) -> None:
    if rng.random() < 0.3:
        _desk_island(rng, placer, catalog)
    for _ in range(int(rng.integers(1, 5))):
        spec = _office_desk(rng, placer, catalog)
        _workplace(rng, placer, catalog, spec and _at_wall(rng, placer, spec, walls, (0.0, 0.06)))
    if rng.random() < 0.15:
        sofa = _choose(rng, catalog, 'sofa', LIVING_SOFAS)
        if sofa is not None:
            _at_wall(rng, placer, sofa, walls, (0.02, 0.1))
    _spare_chairs(rng, placer, catalog, walls, int(rng.integers(0, 3)), GUEST_CHAIRS)
    _room_extras(rng, placer, catalog, layout, walls,
                 {'wastebin': 2, 'plant': 1, 'storage_box': 1.5, 'bag': 1, 'lamp': 0.3},
                 {'bookshelf': 2, 'cabinet': 1.5, 'wardrobe': 0.5}, (3, 8))


def _center_pose(rng, placer: Placer, spec: AssetSpec, yaw: float,
                 jitter: float = 0.6) -> tuple[np.ndarray, float]:
    lo, hi = placer.polygon.min(axis=0), placer.polygon.max(axis=0)
    xy = (lo + hi) / 2 + rng.uniform(-jitter, jitter, size=2) * (hi - lo) / 4
    return np.array([xy[0], xy[1], spec.size[2] / 2]), wrap_angle(yaw + rng.normal(0.0, 0.05))


def _chairs_around(rng, placer: Placer, chair: AssetSpec, table: PlacedObject,
                   share: float) -> None:
    """Chairs around ``table``: along both long sides, one at each end; each with ``share``."""
    if _variant(table.spec) == 'round':
        for k in range(int(rng.integers(3, 7))):
            angle = 2 * np.pi * k / 6 + rng.uniform(-0.2, 0.2)
            if rng.random() < share:
                _chair_at(rng, placer, chair, table, (np.cos(angle), np.sin(angle)))
        return
    seats = max(1, int(table.size[0] / 0.7))
    spots = (np.arange(seats) - (seats - 1) / 2) * table.size[0] / seats
    for side in ((0.0, -1.0), (0.0, 1.0)):
        for along in spots:
            if rng.random() < share:
                _chair_at(rng, placer, chair, table, side, -side[1] * along)
    for side in ((-1.0, 0.0), (1.0, 0.0)):
        if rng.random() < share / 2:
            _chair_at(rng, placer, chair, table, side)


def _central_table(rng, placer: Placer, spec: AssetSpec) -> PlacedObject | None:
    """``spec`` near the middle of the room, along its longer side."""
    lo, hi = placer.polygon.min(axis=0), placer.polygon.max(axis=0)
    yaw = 0.0 if hi[0] - lo[0] >= hi[1] - lo[1] else np.pi / 2
    if rng.random() < 0.5:
        yaw += np.pi
    return placer.place_first_free(
        spec, lambda attempt: _center_pose(rng, placer, spec, yaw, 0.3 + attempt / 8), 16)


def _furnish_meeting(rng, placer, catalog, layout, walls) -> None:
    tables = [s for s in catalog.get('table', ()) if _variant(s) in MEETING_TABLES]
    if tables:
        tables.sort(key=lambda s: -s.size[0])  # meeting tables are the long ones
        spec = tables[int(rng.integers(max(1, len(tables) // 2)))]
        table = _central_table(rng, placer, spec)
        if table is not None:
            chair = _choose(rng, catalog, 'chair', GUEST_CHAIRS + OFFICE_CHAIRS)
            if chair is not None:
                _chairs_around(rng, placer, chair, table, 0.85)
            for _ in range(int(rng.integers(0, 3))):
                kind = ('books', 'keyboard', 'storage_box', 'plant')[int(rng.integers(4))]
                _on_top(rng, placer, table, _household(rng, placer, kind))
    if rng.random() < 0.6:
        stand = _at_wall(rng, placer, _household(rng, placer, 'tv_stand'), walls, (0.0, 0.05),
                         CONTACT)
        if stand is not None:
            _on_top(rng, placer, stand, _household(rng, placer, 'tv'))
    _spare_chairs(rng, placer, catalog, walls, int(rng.integers(0, 4)), GUEST_CHAIRS)
    _room_extras(rng, placer, catalog, layout, walls, {'wastebin': 1, 'plant': 1.5, 'bag': 1},
                 {'cabinet': 1, 'bookshelf': 1}, (1, 5))


def _furnish_living(rng, placer, catalog, layout, walls) -> None:
    sofa_spec = (_furniture(rng, placer, catalog, 'corner_sofa') if rng.random() < 0.3 else
                 _choose(rng, catalog, 'sofa', LIVING_SOFAS))
    sofa = sofa_spec and _at_wall(rng, placer, sofa_spec, walls[:2], (0.02, 0.12))
    if sofa is not None:
        coffee = _furniture(rng, placer, catalog, 'coffee_table')

        def propose(_attempt: int) -> tuple[np.ndarray, float]:
            y = -(sofa.size[1] / 2 + rng.uniform(0.35, 0.6) + coffee.size[1] / 2)
            return _local_pose(sofa, (rng.uniform(-0.2, 0.2), y), coffee,
                               float(rng.normal(0.0, 0.05)))

        table = None if coffee is None else placer.place_first_free(coffee, propose, 8)
        if table is not None:
            for _ in range(int(rng.integers(0, 3))):
                kind = ('books', 'plant', 'storage_box')[int(rng.integers(3))]
                _on_top(rng, placer, table, _household(rng, placer, kind))
            for side in (-1.0, 1.0):  # armchairs or one-seat sofas at the coffee table's ends
                if rng.random() < 0.5:
                    seat = (_furniture(rng, placer, catalog, 'armchair') if rng.random() < 0.6
                            else _choose(rng, catalog, 'sofa', ('1seat', )))
                    _chair_at(rng, placer, seat, table, (side, 0.0), gap=(0.2, 0.5))
            if rng.random() < 0.25:  # a sofa across the coffee table, facing the first
                across = _choose(rng, catalog, 'sofa', ('1seat', '2seat', '3seat'))
                _chair_at(rng, placer, across, table, (0.0, -1.0), gap=(0.35, 0.6))
        for side in (-1, 1):  # end tables, as high as the sofa's arms
            if rng.random() < 0.45:
                end_table = _furniture(rng, placer, catalog, 'side_table')
                end = _next_to(rng, placer, sofa, end_table, side, (0.06, 0.2), None)
                if end is not None and rng.random() < 0.4:
                    _on_top(rng, placer, end, _household(rng, placer, 'lamp'))
    if rng.random() < 0.3:
        second = _choose(rng, catalog, 'sofa', LIVING_SOFAS)
        if second is not None:
            _at_wall(rng, placer, second, walls, (0.02, 0.12))
    if rng.random() < 0.7:
        stand = _at_wall(rng, placer, _household(rng, placer, 'tv_stand'), walls[::-1],
                         (0.0, 0.05), CONTACT)
        if stand is not None and rng.random() < 0.85:
            _on_top(rng, placer, stand, _household(rng, placer, 'tv'))
    if rng.random() < 0.35:  # a dining table with chairs
        spec = _choose(rng, catalog, 'table', DINING_TABLES)
        lo, hi = placer.polygon.min(axis=0), placer.polygon.max(axis=0)
        if spec is not None:
            def anywhere(_attempt: int) -> tuple[np.ndarray, float]:
                xy = rng.uniform(lo + 0.8, hi - 0.8)
                return (np.array([xy[0], xy[1], spec.size[2] / 2]),
                        float(rng.choice([0.0, np.pi / 2])))

            dining = placer.place_first_free(spec, anywhere, 12)
            chair = _choose(rng, catalog, 'chair', GUEST_CHAIRS)
            if dining is not None and chair is not None:
                _chairs_around(rng, placer, chair, dining, 0.6)
    _room_extras(rng, placer, catalog, layout, walls,
                 {'plant': 2, 'lamp': 1.5, 'storage_box': 1, 'bag': 1, 'wastebin': 0.5,
                  'armchair': 0.8},
                 {'bookshelf': 2, 'cabinet': 0.5}, (2, 7))


def _furnish_bedroom(rng, placer, catalog, layout, walls) -> None:
    bed = _at_wall(rng, placer, _household(rng, placer, 'bed'), walls, (0.0, 0.03), CONTACT)
    if bed is not None:
        for side in (-1, 1):
            if rng.random() < 0.8:
                stand = _next_to(rng, placer, bed, _household(rng, placer, 'nightstand'), side)
                if stand is not None and rng.random() < 0.6:
                    _on_top(rng, placer, stand, _household(rng, placer, 'lamp'))
    if rng.random() < 0.85:
        _at_wall(rng, placer, _household(rng, placer, 'wardrobe'), walls, (0.0, 0.03), CONTACT)
    if rng.random() < 0.4:
        spec = _furniture(rng, placer, catalog, 'desk') if rng.random() < 0.5 else _choose(
            rng, catalog, 'table', DESK_TABLES)
        desk = spec and _at_wall(rng, placer, spec, walls, (0.0, 0.06))
        if desk is not None:
            chair = _choose(rng, catalog, 'chair', OFFICE_CHAIRS + GUEST_CHAIRS)
            if chair is not None and rng.random() < 0.8:
                _chair_at(rng, placer, chair, desk, (0.0, -1.0))
            _desk_items(rng, placer, desk, monitors=0.5)
    if rng.random() < 0.2:
        _at_wall(rng, placer, _furniture(rng, placer, catalog, 'armchair'), walls,
                 (0.05, 0.3))
    _room_extras(rng, placer, catalog, layout, walls,
                 {'storage_box': 1.5, 'bag': 1.5, 'wastebin': 0.5, 'plant': 1, 'lamp': 0.5},
                 {'bookshelf': 1, 'tv_stand': 0.3}, (1, 5))


def _furnish_lab(rng, placer, catalog, layout, walls) -> None:
    for _ in range(int(rng.integers(2, 5))):
        spec = _choose(rng, catalog, 'table', LAB_TABLES)
        bench = spec and _at_wall(rng, placer, spec, walls, (0.0, 0.08))
        if bench is None:
            continue
        if rng.random() < 0.7:
            chair = _choose(rng, catalog, 'chair', LAB_CHAIRS)
            if chair is not None:
                _chair_at(rng, placer, chair, bench, (0.0, -1.0), rng.uniform(-0.4, 0.4))
        _desk_items(rng, placer, bench, monitors=0.6)
        for _ in range(int(rng.integers(0, 3))):
            _on_top(rng, placer, bench, _household(rng, placer, 'storage_box'))
    _room_extras(rng, placer, catalog, layout, walls,
                 {'wastebin': 1, 'storage_box': 1.5, 'bag': 0.5, 'plant': 0.3},
                 {'shelf': 1.5, 'cabinet': 1.5, 'bookshelf': 0.5}, (3, 8))


_FURNISH = {
    'office': _furnish_office,
    'meeting': _furnish_meeting,
    'living': _furnish_living,
    'bedroom': _furnish_bedroom,
    'lab': _furnish_lab
}


def furnish_kind(rng: np.random.Generator, placer: Placer, catalog: Catalog,
                 layout: RoomLayout, kind: str) -> None:
    """Furnish ``layout``'s room by the rules of ``kind`` (any kind but the factory)."""
    walls = _walls_by_length(rng, placer.polygon, 1.0)
    _FURNISH[kind](rng, placer, catalog, layout, walls)
