"""Room layouts: shape, openings and objects as boxes and parameters, in plain numpy.

A layout decides what goes where; it knows nothing of Blender. A room is a parametric box
(optionally L- or U-shaped, ``sample_room``) that holds everything, with door and window
openings; it is furnished by the paper's placement rules and factory clutter
(generator/furnish.py) or, with ``room_kinds`` in the configuration, as an office, meeting room,
living room, bedroom or lab by the rules of generator/room_kinds.py. A configuration with a
``hall`` section gives a factory hall instead (generator/hall_layout.py). No two objects
intersect: every placement is checked with oriented-box tests (generator/placement.py) and
dropped when no free position is found after a few tries. Clutter may touch what it stands next
to (no clearance), the detection objects keep ``layout.clearance`` among themselves.

``layout_meta`` turns a layout into the ``room`` and ``objects`` of ``meta.json``.
"""
from typing import Any, Mapping

import numpy as np

from generator.asset_spec import AssetSpec, Catalog
from generator.config import ROOM_KINDS
from generator.furnish import furnish, place_openings
from generator.hall_layout import generate_hall_layout, hall_meta, partition_names
from generator.placement import (CONTACT, EPS, Opening, Partition, PlacedObject, RoomLayout,
                                 boxes_intersect, inward_normals, min_leg_width, offset_polygon,
                                 pick, quad_inside_polygon, rectangles_overlap, room_placer)
from generator.room_kinds import furnish_kind, kind_room_config
from synthdet.classes import GENERATED_CLASSES

__all__ = [
    'CONTACT', 'EPS', 'AssetSpec', 'Catalog', 'Opening', 'Partition', 'PlacedObject', 'RoomLayout',
    'boxes_intersect', 'catalog_from_library', 'generate_hall_layout', 'generate_layout',
    'inward_normals', 'layout_meta', 'min_leg_width', 'offset_polygon', 'partition_names',
    'quad_inside_polygon', 'rectangles_overlap', 'sample_room'
]


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


def generate_layout(rng: np.random.Generator, catalog: Catalog,
                    config: Mapping[str, Any]) -> RoomLayout:
    """Sample one room (or a hall, when ``config`` has a ``hall`` section) and its objects
    following the placement rules (see module docstring)."""
    if 'hall' in config:
        return generate_hall_layout(rng, catalog, config)
    room_cfg, probs, layout_cfg = config['room'], config['probabilities'], config['layout']
    kind = None  # without ``room_kinds`` nothing is drawn: the factory rooms of earlier versions
    if 'room_kinds' in config:
        kind = pick(rng, config['room_kinds'], ROOM_KINDS) or 'factory'
    if kind not in (None, 'factory'):
        room_cfg = kind_room_config(room_cfg, kind)
    shape, polygon, height = sample_room(rng, room_cfg)
    layout = RoomLayout(shape, polygon, height, kind=kind)
    placer = room_placer(polygon, height, config)
    place_openings(rng, placer, room_cfg, layout)

    if kind in (None, 'factory'):
        furnish(rng, placer, catalog, probs, layout_cfg)
    else:
        furnish_kind(rng, placer, catalog, layout, kind)
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
        room.update(hall_meta(layout))
    objects = [{
        'instance': o.instance,
        'class': o.cls,
        'asset': o.spec.asset,
        'params': _jsonable(o.spec.params),
        'box': o.box_dict(),
        'on': o.on
    } for o in layout.objects]
    return {'room': room, 'objects': objects}


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
