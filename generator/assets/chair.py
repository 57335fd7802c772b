"""Procedural chairs: four legs, an office pedestal with a star base, a sled base, industrial /
lab stools, cantilever (Cesca / S 32 style) chairs and stacking chairs with arms; with or without
armrests; panel, slatted, open-frame or rounded backrests. Front faces -y."""
from __future__ import annotations

import math

import numpy as np

from generator.assets import palette
from generator.assets.builder import (MeshBuilder, pick, rot_x, rot_z, rounded_rect, translate,
                                      uniform)

VARIANTS = ('fourleg', 'pedestal', 'sled', 'stool', 'cantilever', 'stacking')
BACKRESTS = ('panel', 'slats', 'frame', 'rounded')


def sample_params(rng: np.random.Generator, index: int) -> tuple[str, dict]:
    """Draw a variant (cycled by index) and its dimensions in metres."""
    variant = VARIANTS[index % len(VARIANTS)]
    office = variant == 'pedestal'
    params = {
        'seat_height':
        uniform(rng, 0.43, 0.52) if office else uniform(rng, 0.42, 0.48),
        'seat_width':
        uniform(rng, 0.44, 0.52) if office else uniform(rng, 0.40, 0.48),
        'seat_depth':
        uniform(rng, 0.42, 0.50) if office else uniform(rng, 0.38, 0.46),
        'seat_thickness':
        uniform(rng, 0.05, 0.09) if office else uniform(rng, 0.02, 0.06),
        'backrest':
        pick(rng, BACKRESTS),
        'back_height':
        uniform(rng, 0.40, 0.68) if office else uniform(rng, 0.32, 0.48),
        'back_tilt':
        uniform(rng, 0.05, 0.25),
        'armrests':
        bool(rng.random() < (0.7 if office else 0.4)),
        'arm_height':
        uniform(rng, 0.18, 0.26),
        'frame_color':
        list(pick(rng, palette.METAL if variant != 'fourleg' else palette.METAL + palette.WOOD)),
        'seat_color':
        list(pick(rng, palette.FABRIC + palette.WOOD[:2])),
    }
    if variant == 'fourleg':
        params['leg_profile'] = pick(rng, ('square', 'round'))
        params['leg_splay'] = uniform(rng, 0.0, 0.03)
        params['stretchers'] = bool(rng.random() < 0.5)
    elif variant == 'pedestal':
        params['base_radius'] = uniform(rng, 0.28, 0.34)
        params['spokes'] = 5
    elif variant == 'stool':  # industrial / lab stool: seat 0.33-0.40 m, 0.55-0.80 m high
        params.update(
            seat_height=uniform(rng, 0.55, 0.80),
            seat_width=uniform(rng, 0.33, 0.40),
            seat_thickness=uniform(rng, 0.04, 0.08),
            stool_base=pick(rng, ('star', 'legs')),
            base_radius=uniform(rng, 0.26, 0.32),
            backrest=pick(rng, ('none', 'pad')),
            back_height=uniform(rng, 0.20, 0.32),
            armrests=False)
        params['seat_depth'] = params['seat_width']
    elif variant == 'cantilever':  # Thonet S 32 / Breuer Cesca: seat 0.46 high, 0.46 wide
        params.update(backrest=pick(rng, ('panel', 'rounded', 'frame')))
    elif variant == 'stacking':  # stacking chair with arms: about 0.55 wide, 0.80 high
        params.update(
            backrest=pick(rng, ('panel', 'rounded')),
            armrests=True,
            seat_width=uniform(rng, 0.44, 0.50),
            seat_thickness=uniform(rng, 0.02, 0.04),
            seat_color=list(pick(rng, palette.PLASTIC)),
            leg_profile='round',
            leg_splay=uniform(rng, 0.01, 0.03),
            stretchers=False)
    return variant, params


def build(variant: str, params: dict) -> MeshBuilder:
    """Build the chair's mesh from its parameters."""
    mb = MeshBuilder()
    frame, seat = mb.materials(params, frame='frame_color', seat='seat_color')
    width, depth = params['seat_width'], params['seat_depth']
    seat_top, thickness = params['seat_height'], params['seat_thickness']
    seat_bottom = seat_top - thickness
    if variant == 'stool':
        _stool(mb, params, frame, seat)
        return mb
    mb.prism(rounded_rect(width, depth, 0.04), thickness, seat, translate(0, 0, seat_bottom))
    if variant in ('fourleg', 'stacking'):
        _four_legs(mb, params, frame)
    elif variant == 'cantilever':
        _cantilever(mb, params, frame)
    elif variant == 'pedestal':
        _pedestal(mb, params, frame)
    elif variant == 'sled':
        _sled(mb, params, frame)
    else:
        raise ValueError(f'unknown chair variant {variant!r}')
    _backrest(mb, variant, params, frame, seat)
    if params['armrests']:
        _armrests(mb, variant, params, frame, seat)
    return mb


def _four_legs(mb: MeshBuilder, params: dict, frame: int) -> None:
    width, depth = params['seat_width'], params['seat_depth']
    top = params['seat_height'] - params['seat_thickness']
    splay = params['leg_splay']
    half = 0.018
    for sx in (-1, 1):
        for sy in (-1, 1):
            x, y = sx * (width / 2 - 0.03), sy * (depth / 2 - 0.03)
            start, end = (x + sx * splay, y + sy * splay, 0.0), (x, y, top)
            if params['leg_profile'] == 'square':
                mb.bar(start, end, 2 * half, 2 * half, frame)
            else:
                mb.rod(start, end, half, frame)
    # apron under the seat
    mb.box_between((-width / 2 + 0.03, -depth / 2 + 0.03, top - 0.06),
                   (width / 2 - 0.03, depth / 2 - 0.03, top), frame)
    if params['stretchers']:
        z = 0.16
        for sx in (-1, 1):
            x = sx * (width / 2 - 0.03 + splay * (1 - z / top))
            mb.rod((x, -depth / 2 + 0.03, z), (x, depth / 2 - 0.03, z), 0.01, frame)


def _star_base(mb: MeshBuilder, radius: float, frame: int, casters: bool, spokes: int = 5) -> None:
    """Spokes from a hub; twin-wheel casters or glides at their tips."""
    for k in range(spokes):
        angle = 2 * math.pi * k / spokes - math.pi / 2
        tip = (radius * math.cos(angle), radius * math.sin(angle))
        mb.bar((0.0, 0.0, 0.10), (tip[0], tip[1], 0.07), 0.04, 0.035, frame)
        if not casters:
            mb.cylinder(0.022, 0.07, frame, translate(tip[0], tip[1], 0.0), segments=10)
            continue
        # twin-wheel caster: a fork under the spoke tip and two wheels across it
        mb.box((0.03, 0.03, 0.03), frame, translate(tip[0], tip[1], 0.055) @ rot_z(angle))
        for side in (-1, 1):
            mb.cylinder(
                0.025,
                0.012,
                frame,
                translate(tip[0], tip[1], 0.025) @ rot_z(angle) @ translate(0, side * 0.008, 0)
                @ rot_x(side * math.pi / 2),
                segments=12)
    mb.cylinder(0.05, 0.08, frame, translate(0, 0, 0.06))


def _stool(mb: MeshBuilder, params: dict, frame: int, seat: int) -> None:
    """Round seat on a gas column over a star base, or on four splayed legs; a foot ring and an
    optional small back pad."""
    seat_top, thickness = params['seat_height'], params['seat_thickness']
    radius = params['seat_width'] / 2
    bottom = seat_top - thickness
    mb.cylinder(radius, thickness, seat, translate(0, 0, bottom), segments=24)
    ring_z = max(0.25, seat_top - 0.42)
    if params['stool_base'] == 'star':
        _star_base(mb, params['base_radius'], frame, casters=False)
        mb.cylinder(0.028, bottom - 0.14, frame, translate(0, 0, 0.14), segments=12)
        ring_r = 0.19
        for k in range(3):
            angle = 2 * math.pi * k / 3 - math.pi / 2
            mb.rod((0, 0, ring_z), (ring_r * math.cos(angle), ring_r * math.sin(angle), ring_z),
                   0.01,
                   frame,
                   segments=8)
    else:
        foot_r, head_r = params['base_radius'] * 0.8, radius * 0.75
        ring_r = head_r + (foot_r - head_r) * (bottom - ring_z) / bottom
        lift = 0.014 * math.sin(math.atan2(foot_r - head_r, bottom))  # the end disc's dip
        for k in range(4):
            angle = 2 * math.pi * k / 4 + math.pi / 4
            c, s = math.cos(angle), math.sin(angle)
            mb.rod((foot_r * c, foot_r * s, lift), (head_r * c, head_r * s, bottom),
                   0.014,
                   frame,
                   segments=8)
    ring = [(ring_r * math.cos(a), ring_r * math.sin(a)) for a in np.linspace(0, 2 * math.pi, 17)]
    for (x0, y0), (x1, y1) in zip(ring, ring[1:]):
        mb.rod((x0, y0, ring_z), (x1, y1, ring_z), 0.009, frame, segments=6)
    if params['backrest'] == 'pad':
        post_y = radius - 0.03
        mb.bar((0, post_y, bottom - 0.02), (0, post_y + 0.04, seat_top + params['back_height']),
               0.04, 0.02, frame)
        mb.prism(
            rounded_rect(0.32, 0.04, 0.015), 0.12, seat,
            translate(0, post_y + 0.05, seat_top + params['back_height'] - 0.12))


def _side_tubes(mb: MeshBuilder, x_side: float, tubes: list[tuple[float, ...]], radius: float,
                frame: int) -> None:
    """The same tubes at x = -x_side and x = x_side; a tube runs from (y, z) to (y, z), given
    as (y start, z start, y end, z end)."""
    for sx in (-1, 1):
        x = sx * x_side
        for y_start, z_start, y_end, z_end in tubes:
            mb.rod((x, y_start, z_start), (x, y_end, z_end), radius, frame)


def _cantilever(mb: MeshBuilder, params: dict, frame: int) -> None:
    """One bent tube per side: floor runner, front upright and seat rail, no back legs."""
    width, depth = params['seat_width'], params['seat_depth']
    top = params['seat_height'] - params['seat_thickness']
    radius = 0.0125
    front, back = -depth / 2, depth / 2 + 0.04
    _side_tubes(mb, width / 2 - 0.01, [
        (back, radius, front - 0.04, radius),
        (front - 0.04, radius, front, top - radius),
        (front, top - radius, depth / 2 - 0.02, top - radius),
    ], radius, frame)
    mb.rod((-width / 2 + 0.01, depth / 2 + 0.04, radius),
           (width / 2 - 0.01, depth / 2 + 0.04, radius), radius, frame)


def _pedestal(mb: MeshBuilder, params: dict, frame: int) -> None:
    top = params['seat_height'] - params['seat_thickness']
    _star_base(mb, params['base_radius'], frame, casters=True, spokes=params['spokes'])
    mb.cylinder(0.028, top - 0.2, frame, translate(0, 0, 0.14), segments=12)
    mb.box_between((-0.11, -0.12, top - 0.06), (0.11, 0.12, top), frame)


def _sled(mb: MeshBuilder, params: dict, frame: int) -> None:
    width, depth = params['seat_width'], params['seat_depth']
    top = params['seat_height'] - params['seat_thickness']
    radius = 0.011
    front, back = -depth / 2 - 0.02, depth / 2 + 0.01
    _side_tubes(mb, width / 2 - 0.02, [
        (front, radius, back, radius),  # runner on the floor
        (front + 0.04, radius, -depth / 2 + 0.04, top),
        (back, radius, depth / 2 - 0.04, top),
    ], radius, frame)
    for y in (-depth / 2 + 0.04, depth / 2 - 0.04):  # cross tubes carrying the seat
        mb.rod((-width / 2 + 0.02, y, top - radius), (width / 2 - 0.02, y, top - radius), radius,
               frame)


def _backrest(mb: MeshBuilder, variant: str, params: dict, frame: int, seat: int) -> None:
    width, depth = params['seat_width'], params['seat_depth']
    height, style = params['back_height'], params['backrest']
    thick = 0.03 if variant != 'pedestal' else 0.06
    base = (
        translate(0, depth / 2 - thick / 2, params['seat_height'] - params['seat_thickness'])
        @ rot_x(-params['back_tilt']))
    panel_width = width - 0.02 if variant != 'pedestal' else width - 0.04
    if variant == 'pedestal':
        # spine from the seat mechanism to the back panel
        mb.bar((0, -depth / 2 + 0.1, 0.0), (0, 0.02, 0.0), 0.06, 0.02, frame, base)
        mb.bar((0, 0.02, -0.01), (0, 0.02, 0.22), 0.06, 0.02, frame, base)
        if height > 0.58:  # executive chairs: a headrest above the tall back
            mb.bar((0, 0.0, height - 0.05), (0, 0.0, height + 0.08), 0.04, 0.015, frame, base)
            mb.prism(
                rounded_rect(0.26, 0.06, 0.025), 0.11, seat,
                base @ translate(0, -0.01, height + 0.06))
    else:
        for sx in (-1, 1):
            x = sx * (width / 2 - 0.03)
            mb.bar((x, 0, 0.0), (x, 0, height), 0.03, 0.03, frame, base)
    lower = 0.12 if variant != 'pedestal' else 0.16
    if style == 'panel':
        mb.box_between((-panel_width / 2, -thick / 2, lower), (panel_width / 2, thick / 2, height),
                       seat, base)
    elif style == 'slats':
        count = 4 if height > 0.4 else 3
        slat = (height - lower) / (2 * count - 1)
        for k in range(count):
            z0 = lower + 2 * k * slat
            mb.box_between((-panel_width / 2, -thick / 4, z0),
                           (panel_width / 2, thick / 4, z0 + slat), seat, base)
    elif style == 'frame':
        rail = 0.06
        mb.box_between((-panel_width / 2, -thick / 2, height - rail),
                       (panel_width / 2, thick / 2, height), seat, base)
        mb.box_between((-panel_width / 2, -thick / 4, lower),
                       (panel_width / 2, thick / 4, lower + rail / 2), frame, base)
        mb.box_between((-0.05, -thick / 4, lower), (0.05, thick / 4, height - rail), frame, base)
    elif style == 'rounded':
        # panel outline in the back's x/z plane: straight sides, an arched top
        arch = 0.25 * panel_width
        outline = [(panel_width / 2, lower),
                   *[(panel_width / 2 * math.cos(a), height - arch + arch * math.sin(a))
                     for a in np.linspace(0.0, math.pi, 13)], (-panel_width / 2, lower)]
        # extrude along -y: rot_x(+pi/2) maps the prism's z to -y and its y to z
        mb.prism(outline, thick, seat, base @ translate(0, thick / 2, 0) @ rot_x(math.pi / 2))
    else:
        raise ValueError(f'unknown backrest {style!r}')


def _armrests(mb: MeshBuilder, variant: str, params: dict, frame: int, seat: int) -> None:
    width, depth = params['seat_width'], params['seat_depth']
    seat_top = params['seat_height']
    arm_z = seat_top + params['arm_height']
    for sx in (-1, 1):
        x = sx * (width / 2 + 0.02)
        if variant == 'pedestal':
            inner = sx * (width / 2 - 0.06)
            mb.bar((inner, 0.02, seat_top - params['seat_thickness'] - 0.01),
                   (x, 0.02, seat_top - params['seat_thickness'] - 0.01), 0.04, 0.02, frame)
            mb.bar((x, 0.02, seat_top - params['seat_thickness'] - 0.02), (x, 0.02, arm_z), 0.04,
                   0.025, frame)
            mb.box_between((x - 0.04, -0.12, arm_z), (x + 0.04, 0.14, arm_z + 0.03), seat)
        elif variant == 'stacking':
            radius = 0.011
            front = (x - sx * 0.01, -depth / 2 + 0.03)
            mb.rod((*front, seat_top - params['seat_thickness']), (*front, arm_z), radius, frame)
            mb.rod((*front, arm_z), (x - sx * 0.01, depth / 2 - 0.03, arm_z), radius, frame)
            mb.box_between((x - sx * 0.01 - 0.022, -depth / 2 + 0.05, arm_z),
                           (x - sx * 0.01 + 0.022, depth / 2 - 0.08, arm_z + 0.02), seat)
        elif variant in ('sled', 'cantilever'):
            radius = 0.011
            mb.rod((x, -depth / 2 + 0.06, seat_top - params['seat_thickness']),
                   (x, -depth / 2 + 0.06, arm_z), radius, frame)
            mb.rod((x, -depth / 2 + 0.06, arm_z), (x, depth / 2 - 0.02, arm_z), radius, frame)
            mb.box_between((x - 0.025, -depth / 2 + 0.04, arm_z),
                           (x + 0.025, depth / 2 - 0.05, arm_z + 0.02), seat)
        else:
            mb.bar((x, -depth / 2 + 0.06, seat_top - params['seat_thickness']),
                   (x, -depth / 2 + 0.06, arm_z), 0.03, 0.03, frame)
            mb.box_between((x - 0.025, -depth / 2 + 0.03, arm_z),
                           (x + 0.025, depth / 2, arm_z + 0.025), frame)
