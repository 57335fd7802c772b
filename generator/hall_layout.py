"""Factory hall layouts: a rectangle cut into a grid of bays, each furnished like a room.

A hall comes from a configuration with a ``hall`` section (generator/config.py). Its bays are
equal rectangles of a side within ``hall.bay``; each is furnished by the factory rules
(generator/furnish.py) and scanned by its own sensor cross. Partition walls, each with a
passage, stand on some of the boundaries between bays; doors and windows are cut into the outer
walls.
"""
import math
from typing import Any, Mapping, Sequence

import numpy as np

from generator.asset_spec import Catalog
from generator.furnish import furnish, place_openings
from generator.placement import EPS, Partition, RoomLayout, room_placer


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
    placer = room_placer(polygon, height, config)
    place_openings(rng, placer, hall_cfg, layout)
    for bay in bays:
        furnish(rng, placer.within(bay), catalog, probs, layout_cfg)
    layout.objects = placer.objects
    return layout


def partition_names(layout: RoomLayout) -> list[str]:
    """Annotation names of a hall's partitions: walls numbered after the outer walls."""
    return [f'wall_{len(layout.polygon) + k}' for k in range(1, len(layout.partitions) + 1)]


def hall_meta(layout: RoomLayout) -> dict[str, Any]:
    """The hall's part of ``meta.json``'s ``room``: its ``bays`` and named ``partitions``."""
    return {
        'bays': [[[float(x), float(y)] for x, y in bay] for bay in layout.bays],
        'partitions': [{
            'instance': name,
            'start': [float(v) for v in p.start],
            'end': [float(v) for v in p.end],
            'passage': [p.u0, p.u1]
        } for name, p in zip(partition_names(layout), layout.partitions)]
    }
