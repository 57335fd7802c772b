"""The factory furnishing rules: the paper's placement rules and the clutter beyond them.

``furnish`` fills a room, or a bay of a hall, through its ``Placer`` (paper, Sec. 3.1):

- each class has an appearance probability;
- tables and sofas stand along the walls and share that space, at most 4 together;
- chairs go at 4 positions on an inner boundary, each with a random rotation;
- yumis and 3D printers stand only on tables, at most one on each local side
  (left = -x, right = +x).

Beyond the paper: factory clutter (class ``clutter``, generator/clutter.py), placed after the
detection objects: shelves, cabinets and machines with their back to a wall, pallets, crates,
carts and bins on the floor (often touching an object), crates on pallets and on free table
tops, pipe runs along the walls or under the ceiling. ``place_openings`` cuts the doors and
windows and keeps each door's swing free. A placement that finds no free position after a few
tries is dropped.
"""
from typing import Any, Mapping, Sequence

import numpy as np

from generator.asset_spec import AssetSpec, Catalog
from generator.clutter import (CLUTTER_KINDS, PRIMITIVE_KINDS, WALL_KINDS, sample_clutter,
                               sample_pipe_run, sample_primitive)
from generator.placement import (CONTACT, EPS, Opening, PlacedObject, Placer, RoomLayout,
                                 facing_yaw, inward_normals, min_leg_width, offset_polygon, pick,
                                 wall_frame, wall_lengths, wrap_angle)
from synthdet.geometry import box_corners_xy, points_in_polygon, rotation2d


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


def _place_wall_item(rng,
                     placer: Placer,
                     spec: AssetSpec,
                     wall: int,
                     gap_range,
                     tries: int = 12) -> PlacedObject | None:
    p0, direction, length, normal = wall_frame(placer.polygon, wall)
    width, depth = spec.size[0], spec.size[1]
    if width > length - 0.2:
        return None
    yaw = facing_yaw(normal)

    def propose(_attempt: int) -> tuple[np.ndarray, float]:
        u = rng.uniform(0.1 + width / 2, length - 0.1 - width / 2)
        gap = rng.uniform(*gap_range)
        xy = p0 + direction * u + normal * (gap + depth / 2)
        return np.array([xy[0], xy[1], spec.size[2] / 2]), yaw

    return placer.place_first_free(spec, propose, tries)


def _place_on_table(rng, placer: Placer, table: PlacedObject, side: int, item: AssetSpec) -> bool:
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
    yaw = wrap_angle(table.yaw + k * np.pi / 2)
    placed = placer.place_first_free(item, lambda _attempt: (center, yaw), 1, on=table.instance)
    return placed is not None


def _crate_above(rng, placer: Placer, support: PlacedObject) -> AssetSpec | None:
    """A crate for the top of ``support`` (as big as a 3D printer on a table), or None when
    less than 25 cm are left under the height limit."""
    room_above = placer.top_limit - (support.base[2] + support.spec.top_z)
    if room_above < 0.25:
        return None
    return sample_clutter(rng, 'crate', room_above, small=support.cls == 'table')


def _place_crate_on_side(rng, placer: Placer, table: PlacedObject, side: int) -> bool:
    """A closed crate as big as a 3D printer on the free ``side`` of ``table``'s top: a hard
    negative for the printers, which stand on the same tables."""
    crate = _crate_above(rng, placer, table)
    return crate is not None and _place_on_table(rng, placer, table, side, crate)


def place_openings(rng, placer: Placer, room_cfg, layout: RoomLayout) -> None:
    """Doors and windows (``room_cfg`` gives how many) on walls long enough, apart from each
    other, into ``layout.openings``; each door's swing a keep-out volume of ``placer``."""
    polygon = layout.polygon
    lengths = wall_lengths(polygon)
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


def _place_clutter(rng, placer: Placer, layout_cfg,
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
        kind = pick(rng, layout_cfg['clutter_kinds'], CLUTTER_KINDS)
        if kind is None:  # rounding left the probabilities a hair below 1
            continue
        if kind in PRIMITIVE_KINDS:
            _place_primitive(rng, placer, kind, layout_cfg['clutter_size'])
        elif kind in WALL_KINDS:
            spec = sample_clutter(rng, kind, placer.top_limit)
            place_against_wall(rng, placer, spec, layout_cfg['wall_gap'])
        elif kind == 'pipe':
            _place_pipe_run(rng, placer, layout_cfg['wall_gap'])
        else:
            if kind == 'crate' and rng.random() < 0.5 and _place_crate_on_top(rng, placer):
                continue
            place_on_floor(rng, placer, sample_clutter(rng, kind, placer.top_limit))


def _place_primitive(rng, placer: Placer, kind: str, size_range) -> None:
    """A plain box or cylinder anywhere on the floor, keeping the clearance (the light clutter
    of earlier versions, drawn exactly as they did)."""
    spec = sample_primitive(rng, kind, size_range)
    lo_xy, hi_xy = placer.polygon.min(axis=0), placer.polygon.max(axis=0)

    def propose(_attempt: int) -> tuple[np.ndarray, float]:
        xy = rng.uniform(lo_xy, hi_xy)
        return np.array([xy[0], xy[1], spec.size[2] / 2]), float(rng.uniform(-np.pi, np.pi))

    placer.place_first_free(spec, propose, 20)


def _draw_wall(rng, lengths: np.ndarray, min_length: float) -> int | None:
    """A wall at least ``min_length`` long, drawn with probability proportional to length."""
    walls = np.flatnonzero(lengths >= min_length)
    if len(walls) == 0:
        return None
    return int(rng.choice(walls, p=lengths[walls] / lengths[walls].sum()))


def _spans_at_wall(placer: Placer, p0: np.ndarray, direction: np.ndarray,
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


def place_against_wall(rng,
                       placer: Placer,
                       spec: AssetSpec,
                       gap_range,
                       tries: int = 12) -> PlacedObject | None:
    """Back to a wall (a gap in ``gap_range``), often side by side with what stands there."""
    width, depth = spec.size[0], spec.size[1]
    lengths = wall_lengths(placer.polygon)
    if _draw_wall(rng, lengths, width + 0.2) is None:
        return None
    spans_of: dict[int, list[tuple[float, float]]] = {}

    def propose(_attempt: int) -> tuple[np.ndarray, float]:
        wall = _draw_wall(rng, lengths, width + 0.2)
        p0, direction, length, normal = wall_frame(placer.polygon, wall)
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
        return np.array([xy[0], xy[1], spec.size[2] / 2]), facing_yaw(normal)

    return placer.place_first_free(spec, propose, tries, clearance=CONTACT)


def _place_pipe_run(rng, placer: Placer, gap_range, tries: int = 12) -> PlacedObject | None:
    """A pipe run along a wall: on the wall (low, or high over the sensor) or hung from the
    ceiling 0.1-1.5 m in front of it."""
    wall = _draw_wall(rng, wall_lengths(placer.polygon), 1.5)
    if wall is None:
        return None
    p0, direction, length, normal = wall_frame(placer.polygon, wall)
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
        return np.array([xy[0], xy[1], z]), facing_yaw(normal)

    return placer.place_first_free(spec, propose, tries, clearance=CONTACT)


def _floor_objects(placer: Placer) -> list[PlacedObject]:
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
    return np.array([xy[0], xy[1], spec.size[2] / 2]), wrap_angle(anchor.yaw + turn * np.pi / 2)


def place_on_floor(rng, placer: Placer, spec: AssetSpec, tries: int = 16) -> None:
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


def _place_crate_on_top(rng, placer: Placer, tries: int = 8) -> bool:
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
                          top_z + spec.size[2] / 2]), wrap_angle(support.yaw + k * np.pi / 2))

    placed = placer.place_first_free(spec, propose, tries, on=support.instance, clearance=CONTACT)
    return placed is not None


def furnish(rng: np.random.Generator, placer: Placer, catalog: Catalog, probs: Mapping[str, float],
            layout_cfg: Mapping[str, Any]) -> None:
    """Place wall items, chairs and clutter in ``placer.polygon`` (a room, or a bay of a hall)."""
    # tables and sofas share the wall slots: the longest walls, at most 4
    polygon = placer.polygon
    lengths = wall_lengths(polygon)
    tie_break = rng.random(len(lengths))
    walls = [int(i) for i in np.lexsort((tie_break, -np.round(lengths, 3)))
             if lengths[i] >= 1.8][:layout_cfg['wall_slots']]
    free_sides: list[tuple[PlacedObject, int]] = []  # table sides left without an item
    for wall in walls:
        cls = pick(rng, probs, ('table', 'sofa'))
        if cls is None or not catalog.get(cls):
            continue
        if cls == 'sofa':
            spec = catalog['sofa'][int(rng.integers(len(catalog['sofa'])))]
            _place_wall_item(rng, placer, spec, wall, layout_cfg['wall_gap'])
            continue
        # decide what goes on the table first, then pick a table whose top holds it
        items = []
        for side in (-1, 1):
            item_cls = pick(rng, probs, ('yumi', '3dprinter'))
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
