"""Procedural tables, office size to workbench size: rectangular tops on four legs, round tops,
pedestal tables, trestle tables, wooden workbenches with a lower shelf, height-adjustable standing
desks, folding tables, industrial steel workbenches, panel-end desks and C-leg desks. The top is
always the highest part, so objects can stand on it; `top_size` (in params) is its usable
rectangle."""
from __future__ import annotations

import math

import numpy as np

from generator.assets import palette
from generator.assets.builder import (MeshBuilder, check_variant, circle, pick, rounded_rect,
                                      translate, uniform)

VARIANTS = ('legs', 'round', 'pedestal', 'trestle', 'workbench', 'standing', 'folding',
            'steelbench', 'panel', 'cleg')
# Variant of instance i is CYCLE[i % 24]: mostly long tables that can carry a printer or a YuMi on
# each half of the top, one round table per 24 (its inscribed square carries only small items).
CYCLE = ('legs', 'workbench', 'standing', 'trestle', 'steelbench', 'pedestal', 'folding', 'panel',
         'legs', 'cleg', 'round', 'standing', 'steelbench', 'trestle', 'folding', 'panel',
         'workbench', 'legs', 'standing', 'pedestal', 'steelbench', 'folding', 'cleg', 'panel')


def sample_params(rng: np.random.Generator, index: int) -> tuple[str, dict]:
    """Draw a variant (from CYCLE by index) and its dimensions in metres."""
    variant = CYCLE[index % len(CYCLE)]
    params: dict = {
        'height': uniform(rng, 0.72, 0.77),
        'top_thickness': uniform(rng, 0.025, 0.04),
        'top_color': list(pick(rng, palette.LAMINATE + palette.WOOD)),
        'frame_color': list(pick(rng, palette.METAL))
    }
    if variant == 'legs':
        params.update(
            width=uniform(rng, 1.4, 2.0),
            depth=uniform(rng, 0.75, 0.9),
            leg_profile=pick(rng, ('square', 'round')),
            apron=bool(rng.random() < 0.6),
            modesty_panel=bool(rng.random() < 0.4))
    elif variant == 'round':
        params.update(diameter=uniform(rng, 1.2, 1.5), legs=int(rng.integers(3, 5)))
    elif variant == 'pedestal':
        params.update(
            width=uniform(rng, 1.2, 1.8),
            depth=uniform(rng, 0.75, 0.9),
            base=pick(rng, ('disc', 'cross')))
    elif variant == 'trestle':
        params.update(width=uniform(rng, 1.6, 2.2), depth=uniform(rng, 0.75, 1.0))
    elif variant == 'workbench':
        params.update(
            width=uniform(rng, 1.5, 2.4),
            depth=uniform(rng, 0.75, 1.0),
            height=uniform(rng, 0.85, 0.95),
            top_thickness=uniform(rng, 0.04, 0.06),
            drawers=bool(rng.random() < 0.5),
            shelf_color=list(pick(rng, palette.WOOD)))
    elif variant == 'standing':  # IKEA BEKANT sit/stand 160 x 80, 65-125 cm; FlexiSpot E7
        params.update(
            width=uniform(rng, 1.2, 1.8),
            depth=uniform(rng, 0.7, 0.8),
            height=uniform(rng, 0.70, 1.05),
            control_side=pick(rng, (-1, 1)))
    elif variant == 'folding':  # 6 ft folding table 183 x 76 x 74 cm, 8 ft 244 x 76 cm
        params.update(
            width=pick(rng, (1.52, 1.83, 2.44)),
            depth=0.76,
            height=0.74,
            top_thickness=0.045,
            top_color=list(pick(rng, ((238, 238, 232), (214, 214, 206), (90, 90, 92)))))
    elif variant == 'steelbench':  # industrial workbench 60-96 x 30-36 in, 34 in high
        params.update(
            width=pick(rng, (1.52, 1.83, 2.13)),
            depth=pick(rng, (0.76, 0.91)),
            height=uniform(rng, 0.84, 0.90),
            top_thickness=uniform(rng, 0.035, 0.05),
            top_color=list(pick(rng, palette.METAL[1:] + ((60, 90, 140), ))),
            frame_color=list(pick(rng, palette.METAL + ((40, 80, 150), (240, 180, 20)))),
            shelf_height=uniform(rng, 0.12, 0.25))
    elif variant == 'panel':  # office desk with panel ends, 140-180 x 80 x 74 cm (EN 527)
        params.update(
            width=uniform(rng, 1.4, 1.8),
            depth=uniform(rng, 0.75, 0.9),
            height=uniform(rng, 0.72, 0.76),
            panel_thickness=uniform(rng, 0.025, 0.04),
            modesty_panel=bool(rng.random() < 0.6))
    elif variant == 'cleg':  # office / bench desk on two C-shaped (cantilever) legs
        params.update(width=uniform(rng, 1.4, 2.0), depth=uniform(rng, 0.75, 0.9))
    if variant == 'round':
        side = params['diameter'] / math.sqrt(2)  # the square inscribed in the round top
        params['top_size'] = [round(side, 4), round(side, 4)]
    else:
        params['top_size'] = [params['width'], params['depth']]
    return variant, params


def build(variant: str, params: dict) -> MeshBuilder:
    """Build the table's mesh from its parameters."""
    mb = MeshBuilder()
    top, frame = mb.materials(params, top='top_color', frame='frame_color')
    height, thick = params['height'], params['top_thickness']
    under = height - thick
    if variant == 'round':
        mb.prism(circle(params['diameter'] / 2, 48), thick, top, translate(0, 0, under))
        _round_legs(mb, params, frame, under)
        return mb
    width, depth = params['width'], params['depth']
    mb.prism(rounded_rect(width, depth, 0.01), thick, top, translate(0, 0, under))
    bases = {
        'legs': _four_legs,
        'pedestal': _pedestal,
        'trestle': _trestle,
        'workbench': _workbench,
        'standing': _standing,
        'folding': _folding,
        'steelbench': _steelbench,
        'panel': _panel_ends,
        'cleg': _c_legs
    }
    check_variant('table', variant, bases)
    bases[variant](mb, params, frame, under)
    return mb


def _four_legs(mb: MeshBuilder, params: dict, frame: int, under: float) -> None:
    width, depth = params['width'], params['depth']
    inset = 0.05
    for sx in (-1, 1):
        for sy in (-1, 1):
            x, y = sx * (width / 2 - inset), sy * (depth / 2 - inset)
            if params['leg_profile'] == 'square':
                mb.box_between((x - 0.025, y - 0.025, 0.0), (x + 0.025, y + 0.025, under), frame)
            else:
                mb.cylinder(0.025, under, frame, translate(x, y, 0.0))
    if params['modesty_panel']:  # office desk: a panel between the back legs
        mb.box_between((-width / 2 + inset, depth / 2 - inset - 0.01, under - 0.40),
                       (width / 2 - inset, depth / 2 - inset + 0.01, under - 0.02), frame)
    if params['apron']:
        mb.box_between((-width / 2 + inset, depth / 2 - inset - 0.01, under - 0.08),
                       (width / 2 - inset, depth / 2 - inset + 0.01, under), frame)
        for sx in (-1, 1):
            x = sx * (width / 2 - inset)
            mb.box_between((x - 0.01, -depth / 2 + inset, under - 0.08),
                           (x + 0.01, depth / 2 - inset, under), frame)


def _round_legs(mb: MeshBuilder, params: dict, frame: int, under: float) -> None:
    radius = params['diameter'] / 2 * 0.6
    count = params['legs']
    for k in range(count):
        angle = 2 * math.pi * k / count + math.pi / 2
        # the foot's tilted end disc dips by rod radius * sin(tilt): lift it onto the floor
        lift = 0.022 * math.sin(math.atan2(0.15 * radius, under))
        foot = (radius * 1.15 * math.cos(angle), radius * 1.15 * math.sin(angle), lift)
        head = (radius * math.cos(angle), radius * math.sin(angle), under)
        mb.rod(foot, head, 0.022, frame)
        mb.rod((0, 0, under - 0.05), (head[0], head[1], under - 0.05), 0.015, frame)
    mb.cylinder(0.08, 0.05, frame, translate(0, 0, under - 0.05))


def _pedestal(mb: MeshBuilder, params: dict, frame: int, under: float) -> None:
    width, depth = params['width'], params['depth']
    if params['base'] == 'disc':
        mb.cylinder(min(0.3, depth / 2 - 0.05), 0.03, frame, segments=32)
        mb.cylinder(0.05, under - 0.03, frame, translate(0, 0, 0.03))
    else:
        half_w, half_d = width / 2 - 0.15, depth / 2 - 0.08
        for sx in (-1, 1):
            mb.cylinder(0.05, under - 0.06, frame, translate(sx * half_w, 0, 0.06))
            mb.box_between((sx * half_w - 0.04, -half_d, 0.0), (sx * half_w + 0.04, half_d, 0.06),
                           frame)
            mb.box_between((sx * half_w - 0.04, -half_d, under - 0.05),
                           (sx * half_w + 0.04, half_d, under), frame)


def _end_frames(mb: MeshBuilder, x_end: float, bars: list[tuple[float, ...]],
                frame: int) -> None:
    """The same frame of bars at x = -x_end and x = x_end; a bar is (half its thickness in x,
    y low, z low, y high, z high)."""
    for sx in (-1, 1):
        x = sx * x_end
        for half, y_low, z_low, y_high, z_high in bars:
            mb.box_between((x - half, y_low, z_low), (x + half, y_high, z_high), frame)


def _trestle(mb: MeshBuilder, params: dict, frame: int, under: float) -> None:
    width, depth = params['width'], params['depth']
    x_end = width / 2 - 0.12
    _end_frames(mb, x_end, [
        (0.035, -depth / 2 + 0.04, 0.0, depth / 2 - 0.04, 0.06),  # foot
        (0.03, -0.06, 0.06, 0.06, under - 0.05),  # upright
        (0.035, -depth / 2 + 0.06, under - 0.05, depth / 2 - 0.06, under),  # top bearer
    ], frame)
    mb.box_between((-x_end, -0.03, 0.25), (x_end, 0.03, 0.35), frame)


def _workbench(mb: MeshBuilder, params: dict, frame: int, under: float) -> None:
    width, depth = params['width'], params['depth']
    shelf = mb.material('shelf', params['shelf_color'])
    inset = 0.04
    for sx in (-1, 1):
        for sy in (-1, 1):
            x, y = sx * (width / 2 - inset), sy * (depth / 2 - inset)
            mb.box_between((x - 0.03, y - 0.03, 0.0), (x + 0.03, y + 0.03, under), frame)
        mb.box_between((sx * (width / 2 - inset) - 0.02, -depth / 2 + inset, 0.12),
                       (sx * (width / 2 - inset) + 0.02, depth / 2 - inset, 0.16), frame)
    mb.box_between((-width / 2 + inset, -depth / 2 + inset + 0.03, under - 0.08),
                   (width / 2 - inset, -depth / 2 + inset - 0.03 + 0.06, under), frame)
    mb.box_between((-width / 2 + inset + 0.03, -depth / 2 + inset, 0.16),
                   (width / 2 - inset - 0.03, depth / 2 - inset, 0.18), shelf)
    if params['drawers']:
        x0 = width / 2 - inset - 0.03 - 0.45
        mb.box_between((x0, -depth / 2 + inset, under - 0.45),
                       (width / 2 - inset - 0.03, depth / 2 - inset - 0.03, under), frame)
        for k in range(3):
            z = under - 0.44 + k * 0.145
            mb.box_between((x0 + 0.02, -depth / 2 + inset - 0.012, z),
                           (width / 2 - inset - 0.05, -depth / 2 + inset, z + 0.135), shelf)


def _standing(mb: MeshBuilder, params: dict, frame: int, under: float) -> None:
    """Two telescoping columns on foot bars, a frame under the top, a control box at the front."""
    width, depth = params['width'], params['depth']
    x_col = width / 2 - 0.18
    outer_top = min(0.64, under - 0.04)
    for sx in (-1, 1):
        x = sx * x_col
        mb.box_between((x - 0.035, -depth / 2 + 0.03, 0.0), (x + 0.035, depth / 2 - 0.03, 0.045),
                       frame)
        mb.box_between((x - 0.04, -0.03, 0.045), (x + 0.04, 0.05, outer_top), frame)
        mb.box_between((x - 0.032, -0.022, outer_top), (x + 0.032, 0.042, under - 0.03), frame)
        mb.box_between((x - 0.03, -depth / 2 + 0.06, under - 0.03),
                       (x + 0.03, depth / 2 - 0.06, under), frame)
    mb.box_between((-x_col, 0.0, under - 0.06), (x_col, 0.04, under - 0.01), frame)
    side = params['control_side']
    mb.box_between((side * (width / 2 - 0.30) - 0.06, -depth / 2 + 0.005, under - 0.025),
                   (side * (width / 2 - 0.30) + 0.06, -depth / 2 + 0.06, under), frame)


def _folding(mb: MeshBuilder, params: dict, frame: int, under: float) -> None:
    """Blow-moulded top with a rim, folding tube legs as two braced U-frames."""
    width, depth = params['width'], params['depth']
    top = mb.material('top', params['top_color'])
    mb.box_between((-width / 2 + 0.02, -depth / 2 + 0.02, under - 0.03),
                   (width / 2 - 0.02, depth / 2 - 0.02, under), top)
    radius = 0.0125
    for sx in (-1, 1):
        x = sx * (width / 2 - 0.12)
        for sy in (-1, 1):
            y = sy * (depth / 2 - 0.07)
            mb.rod((x, y, 0.0), (x, y, under - 0.03), radius, frame, segments=8)
        mb.rod((x, -depth / 2 + 0.07, radius), (x, depth / 2 - 0.07, radius),
               radius,
               frame,
               segments=8)
        # brace from the leg frame to the centre rail under the top
        mb.rod((x, 0.0, radius), (sx * (width / 2 - 0.45), 0.0, under - 0.03),
               0.009,
               frame,
               segments=8)
    mb.box_between((-width / 2 + 0.12, -0.015, under - 0.05),
                   (width / 2 - 0.12, 0.015, under - 0.03), frame)


def _steelbench(mb: MeshBuilder, params: dict, frame: int, under: float) -> None:
    """Square-tube legs with levelling feet, front and side rails, a full-size lower shelf."""
    width, depth = params['width'], params['depth']
    shelf = mb.material('shelf', params['top_color'])
    inset, half = 0.04, 0.025
    for sx in (-1, 1):
        for sy in (-1, 1):
            x, y = sx * (width / 2 - inset), sy * (depth / 2 - inset)
            mb.cylinder(0.03, 0.02, frame, translate(x, y, 0.0), segments=12)
            mb.box_between((x - half, y - half, 0.02), (x + half, y + half, under), frame)
        x = sx * (width / 2 - inset)
        mb.box_between((x - 0.015, -depth / 2 + inset, under - 0.07),
                       (x + 0.015, depth / 2 - inset, under), frame)
    for sy in (-1, 1):
        y = sy * (depth / 2 - inset)
        mb.box_between((-width / 2 + inset, y - 0.015, under - 0.07),
                       (width / 2 - inset, y + 0.015, under), frame)
    z = params['shelf_height']
    mb.box_between((-width / 2 + inset - half, -depth / 2 + inset - half, z - 0.035),
                   (width / 2 - inset + half, depth / 2 - inset + half, z), shelf)


def _panel_ends(mb: MeshBuilder, params: dict, frame: int, under: float) -> None:
    """Two full-depth side panels joined at the back by a metal rail or a modesty panel."""
    width, depth = params['width'], params['depth']
    side = mb.material('panel', params['top_color'])
    thick = params['panel_thickness']
    for sx in (-1, 1):
        x = sx * (width / 2 - 0.02)
        mb.box_between((x - thick / 2, -depth / 2 + 0.02, 0.0),
                       (x + thick / 2, depth / 2 - 0.02, under), side)
    low = under - (0.45 if params['modesty_panel'] else 0.06)  # a modesty panel or a rail
    mb.box_between((-width / 2 + 0.02 + thick / 2, depth / 2 - 0.08, low),
                   (width / 2 - 0.02 - thick / 2, depth / 2 - 0.06, under), frame)


def _c_legs(mb: MeshBuilder, params: dict, frame: int, under: float) -> None:
    """Two C-shaped legs: a foot bar, an upright at the back and an arm under the top."""
    width, depth = params['width'], params['depth']
    x_leg = width / 2 - 0.1
    _end_frames(mb, x_leg, [
        (0.03, -depth / 2 + 0.08, 0.0, depth / 2 - 0.03, 0.04),  # foot bar
        (0.03, depth / 2 - 0.11, 0.04, depth / 2 - 0.03, under),  # upright
        (0.025, -depth / 2 + 0.06, under - 0.04, depth / 2 - 0.11, under),  # arm
    ], frame)
    mb.box_between((-x_leg, depth / 2 - 0.10, under - 0.09),
                   (x_leg, depth / 2 - 0.04, under - 0.01), frame)
