"""Procedural sofas: 1 to 3 seats, with or without arms, seat and back cushions, on feet or on a
plinth; sofas with a chaise longue at one end, armless modular sofas of 2 to 4 modules and
backless lounge benches. A person sitting on it looks towards -y."""
from __future__ import annotations

import numpy as np

from generator.assets import palette
from generator.assets.builder import (MeshBuilder, check_variant, pick, rot_x, rounded_rect,
                                      translate, uniform)

VARIANTS = ('1seat', '2seat', '3seat', 'chaise', 'modular', 'bench')
# Seats per variant (inclusive range). Chaise and modular sofas stay within the 3-seat sofa's
# footprint diagonal (at most 2.75 m): the largest object sets the inference window overlap.
SEATS = {
    '1seat': (1, 1),
    '2seat': (2, 2),
    '3seat': (3, 3),
    'chaise': (2, 2),
    'modular': (2, 3),
    'bench': (2, 3)
}


def sample_params(rng: np.random.Generator, index: int) -> tuple[str, dict]:
    """Draw a variant (cycled by index) and its dimensions in metres."""
    variant = VARIANTS[index % len(VARIANTS)]
    fabric = pick(rng, palette.FABRIC)
    low, high = SEATS[variant]
    params = {
        'seats': int(rng.integers(low, high + 1)),
        'seat_width': uniform(rng, 0.55, 0.70),
        'depth': uniform(rng, 0.80, 0.95),
        'seat_height': uniform(rng, 0.40, 0.46),
        'back_height': uniform(rng, 0.72, 0.92),
        'arms': bool(rng.random() < 0.75),
        'arm_width': uniform(rng, 0.10, 0.24),
        'arm_style': pick(rng, ('rolled', 'square')),
        'arm_height': uniform(rng, 0.55, 0.66),
        'back_cushions': bool(rng.random() < 0.7),
        'base': pick(rng, ('feet', 'plinth')),
        'back_tilt': uniform(rng, 0.08, 0.22),
        'fabric_color': list(fabric),
        'cushion_color': list(fabric if rng.random() < 0.6 else pick(rng, palette.FABRIC)),
        'feet_color': list(pick(rng, palette.WOOD + palette.METAL[:1])),
    }
    if variant == 'chaise':  # chaise longue sections are 1.4-1.7 m deep
        params.update(chaise_depth=uniform(rng, 1.40, 1.70), chaise_side=pick(rng, (-1, 1)))
    elif variant == 'modular':  # armless modules on a plinth, each its own block
        params.update(arms=False, base='plinth', back_cushions=True)
    elif variant == 'bench':  # backless lounge / waiting-room bench, 0.45-0.60 m deep
        params.update(
            seat_width=uniform(rng, 0.55, 0.65),
            depth=uniform(rng, 0.45, 0.60),
            seat_height=uniform(rng, 0.42, 0.46),
            base=pick(rng, ('feet', 'sled')))
    return variant, params


def build(variant: str, params: dict) -> MeshBuilder:
    """Build the sofa's mesh from its parameters."""
    check_variant('sofa', variant, VARIANTS)
    mb = MeshBuilder()
    body, cushion, feet = mb.materials(params, body='fabric_color', cushion='cushion_color',
                                       feet='feet_color')
    if variant == 'bench':
        _bench(mb, params, cushion, feet)
        return mb
    seats, seat_w, depth = params['seats'], params['seat_width'], params['depth']
    arm_w = params['arm_width'] if params['arms'] else 0.0
    inner = seats * seat_w
    width = inner + 2 * arm_w
    lift = 0.10 if params['base'] == 'feet' else 0.0
    if params['base'] == 'feet':
        for sx in (-1, 1):
            for sy in (-1, 1):
                mb.cylinder(
                    0.025,
                    lift,
                    feet,
                    translate(sx * (width / 2 - 0.06), sy * (depth / 2 - 0.06), 0.0),
                    radius_top=0.02)
    else:
        mb.box_between((-width / 2 + 0.03, -depth / 2 + 0.03, 0.0),
                       (width / 2 - 0.03, depth / 2 - 0.03, 0.04), feet)
        lift = 0.04
    back_depth = 0.18
    cushion_h = 0.14
    frame_top = params['seat_height'] - cushion_h
    # seat frame (one block, or one per module) and back frame
    if variant == 'modular':
        for k in range(seats):
            x0 = -inner / 2 + k * seat_w
            mb.box_between((x0 + 0.003, -depth / 2, lift),
                           (x0 + seat_w - 0.003, depth / 2, frame_top), body)
    else:
        mb.box_between((-width / 2, -depth / 2, lift), (width / 2, depth / 2, frame_top), body)
    if variant == 'chaise':
        _chaise(mb, params, body, feet, width, lift, frame_top)
    mb.box_between((-inner / 2, depth / 2 - back_depth, frame_top),
                   (inner / 2, depth / 2, params['back_height']), body)
    if params['arms']:
        for sx in (-1, 1):
            x0 = sx * (inner / 2)
            x1 = sx * (width / 2)
            mb.box_between((min(x0, x1), -depth / 2, frame_top),
                           (max(x0, x1), depth / 2, params['arm_height']), body)
            if params['arm_style'] == 'rolled':
                mb.cylinder(
                    arm_w / 2,
                    depth,
                    body,
                    translate((x0 + x1) / 2, depth / 2, params['arm_height']) @ rot_x(0.5 * np.pi),
                    segments=12)
    # cushions, one per seat, with a small gap between them (the chaise has its own)
    gap = 0.01
    seat_d = depth - back_depth - 0.02
    for k in range(seats):
        x_centre = -inner / 2 + (k + 0.5) * seat_w
        chaise_seat = k == (0 if params.get('chaise_side') == -1 else seats - 1)
        if variant == 'chaise' and chaise_seat:
            seat_d_k = params['chaise_depth'] - back_depth - 0.02
            mb.prism(
                rounded_rect(seat_w - gap, seat_d_k, 0.05), cushion_h, cushion,
                translate(x_centre, depth / 2 - back_depth - seat_d_k / 2, frame_top))
        else:
            mb.prism(
                rounded_rect(seat_w - gap, seat_d, 0.05), cushion_h, cushion,
                translate(x_centre, -depth / 2 + 0.02 + seat_d / 2, frame_top))
        if params['back_cushions']:
            back_h = params['back_height'] - params['seat_height'] - 0.04
            frame = (
                translate(x_centre, depth / 2 - back_depth, params['seat_height'])
                @ rot_x(-params['back_tilt']))
            mb.box_between((-(seat_w - gap) / 2, -0.14, 0.0), ((seat_w - gap) / 2, 0.0, back_h),
                           cushion, frame)
    return mb


def _chaise(mb: MeshBuilder, params: dict, body: int, feet: int, width: float, lift: float,
            frame_top: float) -> None:
    """The chaise longue: the end seat's frame continued forward to `chaise_depth`."""
    seats, seat_w, depth = params['seats'], params['seat_width'], params['depth']
    inner = seats * seat_w
    side = params['chaise_side']
    x_in, x_out = side * (inner / 2 - seat_w), side * width / 2
    front = depth / 2 - params['chaise_depth']
    mb.box_between((min(x_in, x_out), front, lift), (max(x_in, x_out), -depth / 2, frame_top),
                   body)
    if params['base'] == 'feet':
        for x in (x_in + side * 0.06, x_out - side * 0.06):
            mb.cylinder(0.025, lift, feet, translate(x, front + 0.06, 0.0), radius_top=0.02)
    else:
        mb.box_between((min(x_in, x_out) + 0.03 * side, front + 0.03, 0.0),
                       (max(x_in, x_out) - 0.03 * side, -depth / 2, 0.04), feet)


def _bench(mb: MeshBuilder, params: dict, cushion: int, feet: int) -> None:
    """A backless upholstered bench: one seat pad per seat on a frame, on feet or two sled
    frames."""
    seats, seat_w, depth = params['seats'], params['seat_width'], params['depth']
    width = seats * seat_w
    pad = 0.08
    under = params['seat_height'] - pad
    mb.box_between((-width / 2, -depth / 2, under - 0.04), (width / 2, depth / 2, under), feet)
    for k in range(seats):
        x_centre = -width / 2 + (k + 0.5) * seat_w
        mb.prism(
            rounded_rect(seat_w - 0.01, depth, 0.04), pad, cushion, translate(x_centre, 0, under))
    for sx in (-1, 1):
        x = sx * (width / 2 - 0.08)
        if params['base'] == 'feet':
            for sy in (-1, 1):
                mb.box_between((x - 0.02, sy * (depth / 2 - 0.06) - 0.02, 0.0),
                               (x + 0.02, sy * (depth / 2 - 0.06) + 0.02, under - 0.04), feet)
        else:
            mb.box_between((x - 0.015, -depth / 2 + 0.03, 0.0),
                           (x + 0.015, depth / 2 - 0.03, 0.03), feet)
            for sy in (-1, 1):
                mb.box_between((x - 0.015, sy * (depth / 2 - 0.045) - 0.015, 0.03),
                               (x + 0.015, sy * (depth / 2 - 0.045) + 0.015, under - 0.04), feet)
