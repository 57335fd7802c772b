"""Procedural sofas: 1 to 3 seats, with or without arms, seat and back cushions, on feet or on a
plinth. A person sitting on it looks towards -y."""
from __future__ import annotations

import numpy as np

from generator.assets import palette
from generator.assets.builder import MeshBuilder, pick, rot_x, rounded_rect, translate, uniform

VARIANTS = ('1seat', '2seat', '3seat')


def sample_params(rng: np.random.Generator, index: int) -> tuple[str, dict]:
    """Draw a variant (seat count cycled by index) and its dimensions in metres."""
    variant = VARIANTS[index % len(VARIANTS)]
    fabric = pick(rng, palette.FABRIC)
    params = {
        'seats': int(variant[0]),
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
        'fabric_colour': list(fabric),
        'cushion_colour': list(fabric if rng.random() < 0.6 else pick(rng, palette.FABRIC)),
        'feet_colour': list(pick(rng, palette.WOOD + palette.METAL[:1])),
    }
    return variant, params


def build(variant: str, params: dict) -> MeshBuilder:
    """Build the sofa's mesh from its parameters."""
    mb = MeshBuilder()
    body = mb.material('body', params['fabric_colour'])
    cushion = mb.material('cushion', params['cushion_colour'])
    feet = mb.material('feet', params['feet_colour'])
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
    # seat frame and back frame
    mb.box_between((-width / 2, -depth / 2, lift), (width / 2, depth / 2, frame_top), body)
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
    # cushions, one per seat, with a small gap between them
    gap = 0.01
    seat_d = depth - back_depth - 0.02
    for k in range(seats):
        x_centre = -inner / 2 + (k + 0.5) * seat_w
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
