"""Household and office objects: the clutter of offices, meeting rooms, living rooms and bedrooms,
and the furniture of those rooms that the procedural asset library does not build.

Pure numpy, in the style of generator/clutter.py: :func:`sample_household` draws one object as an
:class:`~generator.asset_spec.AssetSpec` (kind, size and parameters, all listed in ``meta.json``) and
:func:`household_mesh` builds its triangles from the spec alone, as closed boxes and cylinders in
the local frame (xy centred, z = 0 at the bottom, front towards -y, back towards +y) whose bounds
are exactly the spec's size.

Clutter kinds (class ``clutter``, asset ``clutter/<kind>``) include what stands on desks and
tables where a 3D printer could stand (monitors, PC towers, boxes, books, lamps, plants), so a
detector learns what is not a printer. Furniture kinds (asset ``furniture/<kind>``) belong to a
detection class: a desk with drawer pedestals and a coffee table (``table``), an armchair
(``chair``) and a corner sofa (``sofa``).
"""
from typing import Any, Callable, Sequence

import numpy as np

from generator.asset_spec import AssetSpec
from generator.assets import palette
from generator.clutter import ColoredSolids, clutter_mesh, line_up_items

CLUTTER_HOUSEHOLD_KINDS = ('monitor', 'pc_tower', 'keyboard', 'books', 'storage_box', 'bag',
                           'lamp', 'plant', 'wastebin', 'tv', 'tv_stand', 'bed', 'nightstand',
                           'wardrobe', 'bookshelf', 'radiator', 'door', 'curtain')
FURNITURE_KINDS = {'desk': 'table', 'coffee_table': 'table', 'side_table': 'table',
                   'armchair': 'chair', 'corner_sofa': 'sofa'}
HOUSEHOLD_KINDS = CLUTTER_HOUSEHOLD_KINDS + tuple(FURNITURE_KINDS)
# objects that carry others on a free top (monitors on desks, a TV on its stand)
SUPPORT_KINDS = ('desk', 'coffee_table', 'side_table', 'tv_stand', 'nightstand')

Size = tuple[float, float, float]

DARK = ((25, 25, 27), (40, 40, 44), (60, 62, 66))
LIGHT = ((225, 225, 220), (200, 200, 196), (240, 240, 236))
FOLIAGE = ((50, 110, 50), (70, 130, 60), (40, 90, 45), (95, 140, 70))
TEXTILE = palette.FABRIC + ((230, 230, 225), (210, 200, 185))
RADIATOR = ((235, 235, 232), (220, 220, 215))


def _mm(value: float) -> float:
    return round(float(value), 3)


def _color(rng: np.random.Generator, options: Sequence[Sequence[int]]) -> list[int]:
    return [int(c) for c in options[int(rng.integers(len(options)))]]


def _fit(rng, low: float, high: float, max_height: float) -> float:
    """A height in [low, high], lowered to fit under ``max_height``."""
    high = min(high, max_height)
    return _mm(rng.uniform(low if low <= high else 0.8 * high, high))


# ----------------------------------------------------------------------------- sampling


def _monitor(rng, max_height):
    width = _mm(rng.uniform(0.48, 0.72))
    height = _fit(rng, 0.36, 0.55, max_height)
    return (width, _mm(rng.uniform(0.16, 0.24)), height), {
        'color': _color(rng, DARK + LIGHT[:1]), 'screen_color': [20, 22, 26],
        'panel_ratio': _mm(rng.uniform(0.55, 0.7))}


def _pc_tower(rng, max_height):
    size = (_mm(rng.uniform(0.17, 0.23)), _mm(rng.uniform(0.38, 0.5)),
            _fit(rng, 0.36, 0.5, max_height))
    return size, {'color': _color(rng, DARK + LIGHT), 'accent_color': _color(rng, DARK)}


def _keyboard(rng, max_height):
    return (_mm(rng.uniform(0.42, 0.47)), _mm(rng.uniform(0.13, 0.17)),
            _mm(rng.uniform(0.022, 0.035))), {'color': _color(rng, DARK + LIGHT)}


def _books(rng, max_height):
    count = int(rng.integers(2, 9))
    thickness = [_mm(rng.uniform(0.015, 0.05)) for _ in range(count)]
    lying = bool(rng.random() < 0.3)
    height = _fit(rng, 0.18, 0.3, max_height)
    depth = _mm(rng.uniform(0.14, 0.22))
    if lying:  # a stack: the books' thickness adds up in z
        size = (height, depth, _mm(sum(thickness)))
    else:  # a row standing side by side
        size = (_mm(sum(thickness)), depth, height)
    colors = [_color(rng, TEXTILE + palette.PLASTIC) for _ in range(count)]
    return size, {'lying': lying, 'thickness': thickness, 'colors': colors}


def _storage_box(rng, max_height):
    style = 'cardboard' if rng.random() < 0.6 else 'plastic'
    size = (_mm(rng.uniform(0.25, 0.6)), _mm(rng.uniform(0.2, 0.45)),
            _fit(rng, 0.15, 0.45, max_height))
    options = palette.CARDBOARD if style == 'cardboard' else palette.PLASTIC
    return size, {'style': style, 'color': _color(rng, options)}


def _bag(rng, max_height):
    style = 'backpack' if rng.random() < 0.6 else 'handbag'
    if style == 'backpack':
        size = (_mm(rng.uniform(0.28, 0.36)), _mm(rng.uniform(0.15, 0.25)),
                _fit(rng, 0.38, 0.5, max_height))
    else:
        size = (_mm(rng.uniform(0.3, 0.45)), _mm(rng.uniform(0.12, 0.2)),
                _fit(rng, 0.3, 0.45, max_height))
    return size, {'style': style, 'color': _color(rng, palette.FABRIC + DARK)}


def _floor_or_small(rng, max_height: float, chance: float, floor_needs: float,
                    floor_ranges: tuple[float, float, float, float],
                    small_ranges: tuple[float, float, float, float]) -> tuple[bool, float, float]:
    """Whether a floor-standing version is drawn (with ``chance``, where ``max_height`` exceeds
    ``floor_needs``), then its width and height, from the (width low, width high, height low,
    height high) ranges of that version."""
    floor = rng.random() < chance and max_height > floor_needs
    width_low, width_high, height_low, height_high = floor_ranges if floor else small_ranges
    return floor, _mm(rng.uniform(width_low, width_high)), _fit(rng, height_low, height_high,
                                                                max_height)


def _lamp(rng, max_height):
    floor, shade, height = _floor_or_small(rng, max_height, 0.4, 1.2, (0.3, 0.45, 1.3, 1.7),
                                           (0.15, 0.28, 0.3, 0.55))
    style = 'floor' if floor else 'desk'
    return (shade, shade, height), {'style': style, 'color': _color(rng, palette.METAL + DARK),
                                    'shade_color': _color(rng, LIGHT + TEXTILE)}


def _plant(rng, max_height):
    floor, width, height = _floor_or_small(rng, max_height, 0.6, 0.7, (0.35, 0.7, 0.6, 1.5),
                                           (0.15, 0.3, 0.2, 0.45))
    style = 'floor' if floor else 'table'
    return (width, width, height), {
        'style': style, 'pot_color': _color(rng, palette.PLASTIC + palette.CARDBOARD),
        'leaf_color': _color(rng, FOLIAGE), 'tiers': int(rng.integers(2, 5))}


def _wastebin(rng, max_height):
    diameter = _mm(rng.uniform(0.24, 0.36))
    return (diameter, diameter, _fit(rng, 0.28, 0.45, max_height)), {
        'color': _color(rng, palette.PLASTIC + palette.METAL)}


def _tv(rng, max_height):
    width = _mm(rng.uniform(0.8, 1.45))
    height = _fit(rng, 0.5 * width + 0.05, 0.58 * width + 0.1, max_height)
    return (width, _mm(rng.uniform(0.2, 0.3)), height), {'color': _color(rng, DARK)}


def _tv_stand(rng, max_height):
    return (_mm(rng.uniform(1.1, 1.8)), _mm(rng.uniform(0.35, 0.45)),
            _fit(rng, 0.4, 0.6, max_height)), {
                'color': _color(rng, palette.WOOD + LIGHT + DARK[:1]),
                'front_color': _color(rng, palette.WOOD + LIGHT + DARK[:1]),
                'compartments': int(rng.integers(2, 4))}


def _bed(rng, max_height):
    width = _mm((0.9, 1.4, 1.6, 1.8)[int(rng.integers(4))] + rng.uniform(0.04, 0.1))
    length = _mm(rng.uniform(2.0, 2.2))
    return (width, length, _fit(rng, 0.8, 1.15, max_height)), {
        'frame_color': _color(rng, palette.WOOD + LIGHT + DARK[:1]),
        'sheet_color': _color(rng, LIGHT + TEXTILE), 'cover_color': _color(rng, TEXTILE),
        'mattress_top': _mm(rng.uniform(0.45, 0.6)), 'pillows': 1 if width < 1.2 else 2}


def _nightstand(rng, max_height):
    return (_mm(rng.uniform(0.38, 0.52)), _mm(rng.uniform(0.33, 0.45)),
            _fit(rng, 0.45, 0.62, max_height)), {
                'color': _color(rng, palette.WOOD + LIGHT), 'drawers': int(rng.integers(1, 4))}


def _wardrobe(rng, max_height):
    width = _mm(rng.uniform(0.8, 2.0))
    return (width, _mm(rng.uniform(0.52, 0.64)), _fit(rng, 1.7, 2.2, max_height)), {
        'color': _color(rng, palette.WOOD + LIGHT), 'doors': max(1, int(round(width / 0.5)))}


def _bookshelf(rng, max_height):
    height = _fit(rng, 0.8, 2.0, max_height)
    return (_mm(rng.uniform(0.6, 1.0)), _mm(rng.uniform(0.26, 0.38)), height), {
        'color': _color(rng, palette.WOOD + LIGHT),
        'levels': max(2, int(height / 0.36)), 'fill': _mm(rng.uniform(0.3, 0.95)),
        'fill_seed': int(rng.integers(2**31))}


def _radiator(rng, max_height):
    return (_mm(rng.uniform(0.6, 1.6)), _mm(rng.uniform(0.08, 0.12)),
            _fit(rng, 0.45, 0.75, max_height)), {'color': _color(rng, RADIATOR)}


def _door(rng, max_height):
    return (_mm(rng.uniform(0.86, 1.06)), 0.06, _fit(rng, 1.95, 2.1, max_height)), {
        'color': _color(rng, palette.WOOD + LIGHT), 'frame_color': _color(rng, LIGHT)}


def _curtain(rng, max_height):
    return (_mm(rng.uniform(0.8, 2.4)), _mm(rng.uniform(0.08, 0.16)),
            _fit(rng, 1.4, 2.4, max_height)), {'color': _color(rng, TEXTILE)}


def _desk(rng, max_height):
    pedestals = int(rng.integers(0, 3))
    return (_mm(rng.uniform(1.2, 1.8)), _mm(rng.uniform(0.65, 0.85)),
            _fit(rng, 0.72, 0.76, max_height)), {
                'top_color': _color(rng, palette.LAMINATE + palette.WOOD),
                'frame_color': _color(rng, palette.METAL + palette.LAMINATE[:2]),
                'pedestals': pedestals, 'modesty_panel': bool(rng.random() < 0.5)}


def _coffee_table(rng, max_height):
    round_top = bool(rng.random() < 0.3)
    width = _mm(rng.uniform(0.6, 0.9) if round_top else rng.uniform(0.8, 1.3))
    depth = width if round_top else _mm(rng.uniform(0.5, 0.7))
    return (width, depth, _fit(rng, 0.35, 0.5, max_height)), {
        'round': round_top, 'top_color': _color(rng, palette.WOOD + LIGHT + DARK[:1]),
        'leg_color': _color(rng, palette.WOOD + palette.METAL), 'shelf': bool(rng.random() < 0.4)}


def _side_table(rng, max_height):
    # an end table beside a sofa or an armchair: as high as their arms, square or round
    round_top = bool(rng.random() < 0.35)
    width = _mm(rng.uniform(0.4, 0.7))
    depth = width if round_top else _mm(rng.uniform(0.4, 0.7))
    return (width, depth, _fit(rng, 0.45, 0.62, max_height)), {
        'round': round_top, 'top_color': _color(rng, palette.WOOD + LIGHT + DARK[:1]),
        'leg_color': _color(rng, palette.WOOD + palette.METAL), 'shelf': bool(rng.random() < 0.5)}


def _armchair(rng, max_height):
    return (_mm(rng.uniform(0.72, 0.95)), _mm(rng.uniform(0.72, 0.9)),
            _fit(rng, 0.75, 1.0, max_height)), {
                'color': _color(rng, palette.FABRIC), 'arm_width': _mm(rng.uniform(0.1, 0.2)),
                'seat_height': _mm(rng.uniform(0.38, 0.45)),
                'feet_color': _color(rng, palette.WOOD + palette.METAL[:1])}


def _corner_sofa(rng, max_height):
    # the footprint diagonal stays under 2.54 m, the library's largest sofa, which sets the
    # inference window overlap
    return (_mm(rng.uniform(1.8, 2.05)), _mm(rng.uniform(1.3, 1.45)),
            _fit(rng, 0.75, 0.9, max_height)), {
                'color': _color(rng, palette.FABRIC), 'seat_depth': _mm(rng.uniform(0.8, 0.92)),
                'seat_height': _mm(rng.uniform(0.4, 0.46)),
                'side': 1 if rng.random() < 0.5 else -1,
                'arm_width': _mm(rng.uniform(0.12, 0.2))}


_SAMPLERS: dict[str, Callable[..., tuple[Size, dict]]] = {
    'monitor': _monitor, 'pc_tower': _pc_tower, 'keyboard': _keyboard, 'books': _books,
    'storage_box': _storage_box, 'bag': _bag, 'lamp': _lamp, 'plant': _plant,
    'wastebin': _wastebin, 'tv': _tv, 'tv_stand': _tv_stand, 'bed': _bed,
    'nightstand': _nightstand, 'wardrobe': _wardrobe, 'bookshelf': _bookshelf,
    'radiator': _radiator, 'door': _door, 'curtain': _curtain, 'desk': _desk,
    'coffee_table': _coffee_table, 'side_table': _side_table, 'armchair': _armchair,
    'corner_sofa': _corner_sofa
}


def sample_household(rng: np.random.Generator, kind: str, max_height: float):
    """Draw one household object of ``kind`` at most ``max_height`` high (an AssetSpec)."""
    size, params = _SAMPLERS[kind](rng, max_height)
    cls = FURNITURE_KINDS.get(kind, 'clutter')
    prefix = 'clutter' if cls == 'clutter' else 'furniture'
    top_z = top_size = None
    if kind in SUPPORT_KINDS:
        top_z, top_size = size[2], (size[0], size[1])
    return AssetSpec(cls, f'{prefix}/{kind}', f'{prefix}/{kind}', {'kind': kind, **params},
                     size, top_z, top_size)


# ----------------------------------------------------------------------------- meshes


def _legs(s: ColoredSolids, w: float, d: float, h: float, side: float, inset: float,
          rgb: Sequence[int]) -> None:
    """Four square legs of ``side`` from the floor to ``h``, ``inset`` from the corners."""
    for x in (-w / 2 + inset, w / 2 - inset - side):
        for y in (-d / 2 + inset, d / 2 - inset - side):
            s.box((x, y, 0), (x + side, y + side, h), rgb)


def _build_monitor(s, size, p):
    w, d, h = size
    panel_h = p['panel_ratio'] * h
    s.box((-0.11, -d / 2, 0), (0.11, d / 2, 0.015), p['color'])  # the foot
    s.box((-0.025, d / 2 - 0.06, 0.015), (0.025, d / 2 - 0.03, h - panel_h + 0.05), p['color'])
    s.box((-w / 2, d / 2 - 0.1, h - panel_h), (w / 2, d / 2 - 0.06, h), p['color'])
    s.box((-w / 2 + 0.015, d / 2 - 0.105, h - panel_h + 0.02), (w / 2 - 0.015, d / 2 - 0.1,
                                                               h - 0.015), p['screen_color'])


def _build_pc_tower(s, size, p):
    w, d, h = size
    s.box((-w / 2, -d / 2 + 0.01, 0.02), (w / 2, d / 2, h), p['color'])
    s.box((-w / 2 + 0.01, -d / 2, 0.02), (w / 2 - 0.01, -d / 2 + 0.01, h - 0.01),
          p['accent_color'])
    _legs(s, w, d, 0.02, 0.03, 0.01, DARK[0])


def _build_keyboard(s, size, p):
    w, d, h = size
    s.box((-w / 2, -d / 2, 0), (w / 2, d / 2, 0.6 * h), p['color'])
    s.box((-w / 2 + 0.01, -d / 2 + 0.01, 0.6 * h), (w / 2 - 0.01, d / 2 - 0.01, h), DARK[1])


def _build_books(s, size, p):
    w, d, h = size
    offset = 0.0
    for thickness, rgb in zip(p['thickness'], p['colors']):
        if p['lying']:
            s.box((-w / 2, -d / 2, offset), (w / 2, d / 2, offset + thickness), rgb)
        else:
            s.box((-w / 2 + offset, -d / 2, 0), (-w / 2 + offset + thickness, d / 2, h), rgb)
        offset += thickness


def _build_storage_box(s, size, p):
    w, d, h = size
    if p['style'] == 'cardboard':  # a closed box with a tape strip
        s.box((-w / 2, -d / 2, 0), (w / 2, d / 2, h - 0.002), p['color'])
        s.box((-0.025, -d / 2, h - 0.002), (0.025, d / 2, h), (200, 190, 160))
    else:  # a tapered tub under its lid
        s.box((-w / 2 + 0.01, -d / 2 + 0.01, 0), (w / 2 - 0.01, d / 2 - 0.01, h - 0.02),
              p['color'])
        s.box((-w / 2, -d / 2, h - 0.02), (w / 2, d / 2, h), p['color'])


def _build_bag(s, size, p):
    w, d, h = size
    if p['style'] == 'backpack':
        s.box((-w / 2, -d / 2 + 0.04, 0), (w / 2, d / 2, h - 0.06), p['color'])
        s.box((-w / 2 + 0.04, -d / 2, 0.04), (w / 2 - 0.04, -d / 2 + 0.04, 0.5 * h), p['color'])
        s.box((-0.05, -0.01, h - 0.06), (0.05, 0.01, h), p['color'])  # the carry loop
    else:
        s.box((-w / 2, -d / 2, 0), (w / 2, d / 2, 0.7 * h), p['color'])
        for x in (-w / 4, w / 4 - 0.015):  # the handles
            s.box((x, -0.01, 0.7 * h), (x + 0.015, 0.01, h), p['color'])


def _build_lamp(s, size, p):
    w, _, h = size
    shade_h = min(0.35 * h, 0.35 if p['style'] == 'floor' else 0.18)
    s.cylinder((0, 0, 0), 2, w / 2 * 0.7, 0.02, p['color'])
    s.cylinder((0, 0, 0.02), 2, 0.012, h - shade_h - 0.02, p['color'], segments=8)
    s.cylinder((0, 0, h - shade_h), 2, w / 2, shade_h, p['shade_color'])


def _build_plant(s, size, p):
    w, _, h = size
    pot_h = 0.3 * h
    s.cylinder((0, 0, 0), 2, 0.35 * w, pot_h, p['pot_color'])
    tiers = p['tiers']
    step = (h - pot_h) / tiers
    # foliage: tiers that widen to the middle, then narrow; the widest one fills the size
    shape = 0.6 + 0.4 * np.sin(np.pi * (np.arange(tiers) + 0.5) / tiers)
    for k, radius in enumerate(w / 2 * shape / shape.max()):
        s.cylinder((0, 0, pot_h + k * step), 2, radius, step, p['leaf_color'], segments=8)


def _build_wastebin(s, size, p):
    w, _, h = size
    s.cylinder((0, 0, 0), 2, w / 2 - 0.01, h - 0.02, p['color'])
    s.cylinder((0, 0, h - 0.02), 2, w / 2, 0.02, p['color'])


def _build_tv(s, size, p):
    w, d, h = size
    s.box((-0.2, -d / 2, 0), (0.2, d / 2, 0.02), p['color'])  # the foot
    s.box((-0.04, -0.02, 0.02), (0.04, 0.02, 0.12), p['color'])
    s.box((-w / 2, -0.03, 0.08), (w / 2, 0.03, h), p['color'])
    s.box((-w / 2 + 0.015, -0.035, 0.095), (w / 2 - 0.015, -0.03, h - 0.015), (15, 16, 18))


def _build_tv_stand(s, size, p):
    w, d, h = size
    s.box((-w / 2 + 0.03, -d / 2 + 0.03, 0), (w / 2 - 0.03, d / 2 - 0.03, 0.05), DARK[1])
    s.box((-w / 2, -d / 2 + 0.02, 0.05), (w / 2, d / 2, h - 0.02), p['color'])
    s.box((-w / 2, -d / 2, h - 0.02), (w / 2, d / 2, h), p['color'])
    xs = np.linspace(-w / 2, w / 2, p['compartments'] + 1)
    for x0, x1 in zip(xs[:-1], xs[1:]):
        s.box((x0 + 0.01, -d / 2, 0.07), (x1 - 0.01, -d / 2 + 0.02, h - 0.04), p['front_color'])


def _build_bed(s, size, p):
    w, d, h = size
    top = p['mattress_top']
    head = 0.06  # the headboard at +y
    s.box((-w / 2, -d / 2, 0), (w / 2, d / 2 - head, top - 0.18), p['frame_color'])
    s.box((-w / 2, d / 2 - head, 0), (w / 2, d / 2, h), p['frame_color'])
    s.box((-w / 2 + 0.02, -d / 2 + 0.02, top - 0.18), (w / 2 - 0.02, d / 2 - head, top - 0.04),
          p['sheet_color'])
    s.box((-w / 2, -d / 2, top - 0.04), (w / 2, d / 2 - head - 0.5, top), p['cover_color'])
    pillow_w = (w - 0.1) / p['pillows']
    for k in range(p['pillows']):
        x0 = -w / 2 + 0.05 + k * pillow_w
        s.box((x0 + 0.02, d / 2 - head - 0.45, top - 0.04),
              (x0 + pillow_w - 0.02, d / 2 - head - 0.05, min(top + 0.1, h - 0.01)), LIGHT[2])


def _drawer_front(s, x0, x1, z0, z1, y, rgb):
    s.box((x0 + 0.005, y, z0 + 0.005), (x1 - 0.005, y + 0.02, z1 - 0.005), rgb)
    xc, zc = (x0 + x1) / 2, z1 - 0.05
    s.box((xc - 0.05, y - 0.015, zc - 0.008), (xc + 0.05, y, zc + 0.008), palette.METAL[2])


def _build_nightstand(s, size, p):
    w, d, h = size
    s.box((-w / 2, -d / 2 + 0.035, 0), (w / 2, d / 2, h), p['color'])
    zs = np.linspace(0.06, h - 0.02, p['drawers'] + 1)
    for z0, z1 in zip(zs[:-1], zs[1:]):
        _drawer_front(s, -w / 2, w / 2, z0, z1, -d / 2 + 0.015, p['color'])


def _build_wardrobe(s, size, p):
    w, d, h = size
    s.box((-w / 2, -d / 2 + 0.04, 0), (w / 2, d / 2, h), p['color'])
    xs = np.linspace(-w / 2, w / 2, p['doors'] + 1)
    for k, (x0, x1) in enumerate(zip(xs[:-1], xs[1:])):
        s.box((x0 + 0.003, -d / 2 + 0.02, 0.08), (x1 - 0.003, -d / 2 + 0.04, h - 0.02),
              p['color'])
        xh = x1 - 0.05 if k % 2 == 0 else x0 + 0.04
        s.box((xh, -d / 2, 0.45 * h), (xh + 0.015, -d / 2 + 0.02, 0.45 * h + 0.25),
              palette.METAL[2])


def _build_bookshelf(s, size, p):
    w, d, h = size
    side, board = 0.02, 0.02
    for x in (-w / 2, w / 2 - side):
        s.box((x, -d / 2, 0), (x + side, d / 2, h), p['color'])
    s.box((-w / 2 + side, d / 2 - 0.01, 0), (w / 2 - side, d / 2, h), p['color'])
    levels = np.linspace(0.0, h - board, p['levels'] + 1)
    for z in levels:
        s.box((-w / 2 + side, -d / 2, z), (w / 2 - side, d / 2 - 0.01, z + board), p['color'])
    fill = np.random.default_rng(p['fill_seed'])  # books on the boards, fixed by the spec

    def book(x, thick, z0, z1):
        top = z0 + fill.uniform(0.6, 0.95) * (z1 - z0 - 0.01)
        s.box((x, -d / 2 + 0.02, z0), (x + thick, d / 2 - 0.02, top),
              _color(fill, TEXTILE + palette.PLASTIC))

    line_up_items(fill, zip(levels[:-1] + board, levels[1:]),
                  (-w / 2 + side + 0.01, w / 2 - side - 0.01), (0.015, 0.05), (0.0, 0.01),
                  p['fill'], book)


def _build_radiator(s, size, p):
    w, d, h = size
    for x in (-w / 2 + 0.05, w / 2 - 0.09):  # the feet
        s.box((x, -0.02, 0), (x + 0.04, 0.02, 0.12), p['color'])
    columns = max(2, int(w / 0.05))
    xs = np.linspace(-w / 2, w / 2, columns + 1)
    for k, (x0, x1) in enumerate(zip(xs[:-1], xs[1:])):  # sections with a gap between them
        gap_left, gap_right = 0.004 * (k > 0), 0.004 * (k < columns - 1)
        s.box((x0 + gap_left, -d / 2, 0.12), (x1 - gap_right, d / 2, h), p['color'])


def _build_door(s, size, p):
    w, d, h = size
    s.box((-w / 2, 0.0, 0), (-w / 2 + 0.05, d / 2, h), p['frame_color'])
    s.box((w / 2 - 0.05, 0.0, 0), (w / 2, d / 2, h), p['frame_color'])
    s.box((-w / 2 + 0.05, -d / 2 + 0.02, 0.005), (w / 2 - 0.05, d / 2, h - 0.03), p['color'])
    s.box((-w / 2 + 0.05, 0.0, h - 0.03), (w / 2 - 0.05, d / 2, h), p['frame_color'])
    s.box((w / 2 - 0.15, -d / 2, 0.95), (w / 2 - 0.1, -d / 2 + 0.02, 1.1), palette.METAL[1])


def _build_curtain(s, size, p):
    w, d, h = size
    folds = max(2, int(w / 0.12))
    xs = np.linspace(-w / 2, w / 2, folds + 1)
    for k, (x0, x1) in enumerate(zip(xs[:-1], xs[1:])):  # pleats, alternately forward and back
        y0 = -d / 2 if k % 2 == 0 else 0.0
        s.box((x0, y0, 0.0), (x1, y0 + d / 2, h - 0.04), p['color'])
    s.cylinder((-w / 2, d / 4, h - 0.02), 0, 0.02, w, palette.METAL[2], segments=8)


def _build_desk(s, size, p):
    w, d, h = size
    top = 0.025
    s.box((-w / 2, -d / 2, h - top), (w / 2, d / 2, h), p['top_color'])
    pedestal_w = 0.42
    sides = {0: (), 1: (1, ), 2: (-1, 1)}[p['pedestals']]
    for side in (-1, 1):
        x0 = -w / 2 if side < 0 else w / 2 - pedestal_w
        if side in sides:  # a drawer pedestal under the top
            s.box((x0, -d / 2 + 0.05, 0), (x0 + pedestal_w, d / 2 - 0.02, h - top),
                  p['frame_color'])
            zs = np.linspace(0.04, h - top - 0.01, 4)
            for z0, z1 in zip(zs[:-1], zs[1:]):
                _drawer_front(s, x0 + 0.01, x0 + pedestal_w - 0.01, z0, z1, -d / 2 + 0.03,
                              p['frame_color'])
        else:  # a panel leg
            xl = -w / 2 + 0.02 if side < 0 else w / 2 - 0.05
            s.box((xl, -d / 2 + 0.03, 0), (xl + 0.03, d / 2 - 0.03, h - top), p['frame_color'])
    if p['modesty_panel']:
        s.box((-w / 2 + 0.05, d / 2 - 0.05, 0.35), (w / 2 - 0.05, d / 2 - 0.03, h - top),
              p['frame_color'])


def _build_coffee_table(s, size, p):
    w, d, h = size
    top = 0.03
    if p['round']:
        s.cylinder((0, 0, h - top), 2, w / 2, top, p['top_color'], segments=24)
        s.cylinder((0, 0, 0), 2, 0.25 * w, 0.02, p['leg_color'])
        s.cylinder((0, 0, 0.02), 2, 0.04, h - top - 0.02, p['leg_color'])
        return
    s.box((-w / 2, -d / 2, h - top), (w / 2, d / 2, h), p['top_color'])
    _legs(s, w, d, h - top, 0.04, 0.03, p['leg_color'])
    if p['shelf']:
        s.box((-w / 2 + 0.07, -d / 2 + 0.07, 0.1), (w / 2 - 0.07, d / 2 - 0.07, 0.12),
              p['top_color'])


def _build_armchair(s, size, p):
    w, d, h = size
    arm, seat = p['arm_width'], p['seat_height']
    _legs(s, w, d, 0.08, 0.04, 0.03, p['feet_color'])
    s.box((-w / 2, -d / 2, 0.08), (w / 2, d / 2, seat - 0.1), p['color'])
    s.box((-w / 2 + arm, -d / 2, seat - 0.1), (w / 2 - arm, d / 2 - 0.18, seat), p['color'])
    s.box((-w / 2, d / 2 - 0.18, seat - 0.1), (w / 2, d / 2, h), p['color'])  # the back
    for x in (-w / 2, w / 2 - arm):
        s.box((x, -d / 2, seat - 0.1), (x + arm, d / 2 - 0.18, seat + 0.22), p['color'])


def _build_corner_sofa(s, size, p):
    w, d, h = size
    seat_d, seat, arm, back = p['seat_depth'], p['seat_height'], p['arm_width'], 0.2
    y_back = d / 2 - seat_d  # the main part's front edge
    s.box((-w / 2, y_back, 0.05), (w / 2, d / 2, seat), p['color'])  # main seat block
    s.box((-w / 2, d / 2 - back, seat), (w / 2, d / 2, h), p['color'])  # the back
    # the chaise longue at one end reaches forward to -d/2
    x0, x1 = (w / 2 - seat_d, w / 2) if p['side'] > 0 else (-w / 2, -w / 2 + seat_d)
    s.box((x0, -d / 2, 0.05), (x1, y_back, seat), p['color'])
    xa = -w / 2 if p['side'] > 0 else w / 2 - arm  # an arm at the other end
    s.box((xa, y_back, seat), (xa + arm, d / 2 - back, seat + 0.2), p['color'])
    for x in (-w / 2 + 0.05, w / 2 - 0.09):
        for y in (-d / 2 + 0.05, d / 2 - 0.09):
            if y < y_back and not x0 <= x <= x1 - 0.04:
                continue  # no foot under the open floor in front of the main part
            s.box((x, y, 0), (x + 0.04, y + 0.04, 0.05), DARK[1])


_BUILDERS: dict[str, Callable[[ColoredSolids, Size, dict], None]] = {
    'monitor': _build_monitor, 'pc_tower': _build_pc_tower, 'keyboard': _build_keyboard,
    'books': _build_books, 'storage_box': _build_storage_box, 'bag': _build_bag,
    'lamp': _build_lamp, 'plant': _build_plant, 'wastebin': _build_wastebin, 'tv': _build_tv,
    'tv_stand': _build_tv_stand, 'bed': _build_bed, 'nightstand': _build_nightstand,
    'wardrobe': _build_wardrobe, 'bookshelf': _build_bookshelf, 'radiator': _build_radiator,
    'door': _build_door, 'curtain': _build_curtain, 'desk': _build_desk,
    'coffee_table': _build_coffee_table, 'side_table': _build_coffee_table,
    'armchair': _build_armchair,
    'corner_sofa': _build_corner_sofa
}


def household_mesh(spec: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertices (V, 3), triangles (T, 3) and colors (T, 3) uint8 of a household spec, in its
    local frame."""
    solids = ColoredSolids()
    _BUILDERS[spec.params['kind']](solids, tuple(spec.size), spec.params)
    return solids.arrays()


def is_procedural(spec: Any) -> bool:
    """True for objects built from their spec (clutter and household furniture), not taken from
    the asset library."""
    return spec.cls == 'clutter' or spec.asset.startswith('furniture/')


def procedural_mesh(spec: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The mesh of a clutter or household spec, whichever module builds its kind."""
    if spec.params['kind'] in _BUILDERS:
        return household_mesh(spec)
    return clutter_mesh(spec)
