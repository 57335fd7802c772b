"""Procedural tables, office size to workbench size: rectangular tops on four legs, round tops,
pedestal tables, trestle tables and workbenches with a lower shelf. The top is always the highest
part, so objects can stand on it; `top_size` (in params) is its usable rectangle."""
from __future__ import annotations

import math

import numpy as np

from generator.assets import palette
from generator.assets.builder import (MeshBuilder, circle, pick, rounded_rect, translate, uniform)

VARIANTS = ('legs', 'round', 'pedestal', 'trestle', 'workbench')
# Variant of instance i is CYCLE[i % 12]: mostly long tables that can carry a printer or a YuMi on
# each half of the top, one round table per 12 (its inscribed square carries only small items).
CYCLE = ('legs', 'workbench', 'trestle', 'pedestal', 'legs', 'round', 'workbench', 'trestle',
         'legs', 'pedestal', 'workbench', 'trestle')


def sample_params(rng: np.random.Generator, index: int) -> tuple[str, dict]:
    """Draw a variant (from CYCLE by index) and its dimensions in metres."""
    variant = CYCLE[index % len(CYCLE)]
    params: dict = {
        'height': uniform(rng, 0.72, 0.77),
        'top_thickness': uniform(rng, 0.025, 0.04),
        'top_colour': list(pick(rng, palette.LAMINATE + palette.WOOD)),
        'frame_colour': list(pick(rng, palette.METAL))
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
            shelf_colour=list(pick(rng, palette.WOOD)))
    if variant == 'round':
        side = params['diameter'] / math.sqrt(2)  # the square inscribed in the round top
        params['top_size'] = [round(side, 4), round(side, 4)]
    else:
        params['top_size'] = [params['width'], params['depth']]
    return variant, params


def build(variant: str, params: dict) -> MeshBuilder:
    """Build the table's mesh from its parameters."""
    mb = MeshBuilder()
    top = mb.material('top', params['top_colour'])
    frame = mb.material('frame', params['frame_colour'])
    height, thick = params['height'], params['top_thickness']
    under = height - thick
    if variant == 'round':
        mb.prism(circle(params['diameter'] / 2, 48), thick, top, translate(0, 0, under))
        _round_legs(mb, params, frame, under)
        return mb
    width, depth = params['width'], params['depth']
    mb.prism(rounded_rect(width, depth, 0.01), thick, top, translate(0, 0, under))
    if variant == 'legs':
        _four_legs(mb, params, frame, under)
    elif variant == 'pedestal':
        _pedestal(mb, params, frame, under)
    elif variant == 'trestle':
        _trestle(mb, params, frame, under)
    elif variant == 'workbench':
        _workbench(mb, params, frame, under)
    else:
        raise ValueError(f'unknown table variant {variant!r}')
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
        foot = (radius * 1.15 * math.cos(angle), radius * 1.15 * math.sin(angle), 0.0)
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


def _trestle(mb: MeshBuilder, params: dict, frame: int, under: float) -> None:
    width, depth = params['width'], params['depth']
    x_end = width / 2 - 0.12
    for sx in (-1, 1):
        x = sx * x_end
        mb.box_between((x - 0.035, -depth / 2 + 0.04, 0.0), (x + 0.035, depth / 2 - 0.04, 0.06),
                       frame)
        mb.box_between((x - 0.03, -0.06, 0.06), (x + 0.03, 0.06, under - 0.05), frame)
        mb.box_between((x - 0.035, -depth / 2 + 0.06, under - 0.05),
                       (x + 0.035, depth / 2 - 0.06, under), frame)
    mb.box_between((-x_end, -0.03, 0.25), (x_end, 0.03, 0.35), frame)


def _workbench(mb: MeshBuilder, params: dict, frame: int, under: float) -> None:
    width, depth = params['width'], params['depth']
    shelf = mb.material('shelf', params['shelf_colour'])
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
