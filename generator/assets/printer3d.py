"""Procedural 3D printers (class `3dprinter`), strongly varied: enclosed box printers (door
closed, absent or swung open), bed-slingers, deltas, large-format machines, open-frame CoreXY
cubes, resin (MSLA / SLA) printers with a colored lid, compact cantilever bed-slingers and
Ultimaker-style box frames. Filament printers have frame, bed, gantry / print head and a spool.
The door or display faces -y."""
from __future__ import annotations

import math

import numpy as np

from generator.assets import palette
from generator.assets.builder import (MeshBuilder, check_variant, pick, rot_x, rot_y, rot_z,
                                      translate, uniform)

VARIANTS = ('enclosed', 'bedslinger', 'delta', 'largeformat', 'corexy', 'resin', 'cantilever',
            'boxframe')
# translucent UV-blocking lids of resin printers: orange, yellow, red, green, smoke
RESIN_LIDS = ((245, 120, 20), (240, 200, 30), (200, 40, 40), (60, 160, 70), (90, 80, 70))


def _outer_size(rng: np.random.Generator, width: tuple[float, float],
                depth: tuple[float, float], height: tuple[float, float]) -> dict:
    """The printer's outer width, depth and height in metres, drawn in that order from their
    (low, high) ranges."""
    return {
        'width': uniform(rng, *width),
        'depth': uniform(rng, *depth),
        'height': uniform(rng, *height)
    }


def sample_params(rng: np.random.Generator, index: int) -> tuple[str, dict]:
    """Draw a variant (cycled by index) and its dimensions in metres."""
    variant = VARIANTS[index % len(VARIANTS)]
    params: dict = {
        'body_color': list(pick(rng, palette.PRINTER_BODY)),
        'frame_color': list(pick(rng, palette.METAL)),
        'bed_color': list(pick(rng, ((30, 30, 30), (190, 190, 195), (170, 140, 60)))),
        'filament_color': list(pick(rng, palette.FILAMENT)),
        'spool': pick(rng, ('top', 'side', 'back'))
    }
    if variant == 'enclosed':
        params.update(
            _outer_size(rng, (0.38, 0.55), (0.40, 0.60), (0.45, 0.80)),
            door=pick(rng, ('glass', 'open', 'swung')),
            bed_level=uniform(rng, 0.2, 0.8))
    elif variant == 'bedslinger':
        params.update(
            _outer_size(rng, (0.40, 0.52), (0.36, 0.46), (0.42, 0.58)),
            bed_size=uniform(rng, 0.22, 0.26),
            bed_travel=uniform(rng, -1.0, 1.0),
            gantry_level=uniform(rng, 0.1, 0.9),
            head_travel=uniform(rng, -1.0, 1.0))
    elif variant == 'delta':
        params.update(
            side=uniform(rng, 0.30, 0.45),
            height=uniform(rng, 0.60, 0.90),
            effector=[uniform(rng, -0.6, 0.6),
                      uniform(rng, -0.6, 0.6),
                      uniform(rng, 0.05, 0.5)])
    elif variant == 'largeformat':
        params.update(
            _outer_size(rng, (0.60, 0.80), (0.60, 0.80), (0.60, 0.90)),
            frame=pick(rng, ('open', 'cabinet')),
            bed_level=uniform(rng, 0.1, 0.8),
            head_travel=uniform(rng, -1.0, 1.0))
    elif variant == 'corexy':  # open-frame CoreXY cube (Voron 2.4 / RatRig V-Core without panels)
        params.update(
            _outer_size(rng, (0.42, 0.58), (0.42, 0.58), (0.48, 0.68)),
            bed_level=uniform(rng, 0.1, 0.9),
            head=[uniform(rng, -1.0, 1.0), uniform(rng, -1.0, 1.0)])
    elif variant == 'resin':  # MSLA 0.23 x 0.23 x 0.40 (Elegoo Mars) to SLA 0.41 x 0.38 x 0.53
        params.update(
            _outer_size(rng, (0.22, 0.42), (0.22, 0.40), (0.38, 0.55)),
            base_fraction=uniform(rng, 0.25, 0.40),
            lid_style=pick(rng, ('box', 'hinged')),
            lid_color=list(pick(rng, RESIN_LIDS)))
    elif variant == 'cantilever':  # Prusa MINI+ 0.33 x 0.34 x 0.38, Bambu Lab A1 mini
        params.update(
            _outer_size(rng, (0.30, 0.36), (0.30, 0.36), (0.34, 0.40)),
            bed_travel=uniform(rng, -1.0, 1.0),
            gantry_level=uniform(rng, 0.1, 0.9),
            head_travel=uniform(rng, -1.0, 1.0),
            column_side=pick(rng, (-1, 1)))
    elif variant == 'boxframe':  # Ultimaker 2+ 0.34 x 0.36 x 0.39 to S5 0.50 x 0.59 x 0.78
        params.update(
            _outer_size(rng, (0.34, 0.50), (0.36, 0.59), (0.39, 0.78)),
            door=pick(rng, ('none', 'glass')),
            bed_level=uniform(rng, 0.1, 0.9),
            head=[uniform(rng, -1.0, 1.0), uniform(rng, -1.0, 1.0)])
    return variant, params


def build(variant: str, params: dict) -> MeshBuilder:
    """Build the printer's mesh from its parameters."""
    mb = MeshBuilder()
    builders = {
        'enclosed': _enclosed,
        'bedslinger': _bedslinger,
        'delta': _delta,
        'largeformat': _largeformat,
        'corexy': _corexy,
        'resin': _resin,
        'cantilever': _cantilever,
        'boxframe': _boxframe
    }
    check_variant('3dprinter', variant, builders)
    builders[variant](mb, params)
    return mb


def _materials(mb: MeshBuilder, params: dict) -> tuple[int, int, int, int]:
    return mb.materials(params, body='body_color', frame='frame_color', bed='bed_color',
                        filament='filament_color')


def _spool(mb: MeshBuilder, centre, filament: int, frame: int, axis: str = 'x') -> None:
    """A filament spool on a short hub, its axis horizontal along x or y, centred at `centre`."""
    turn = rot_y(math.pi / 2) if axis == 'x' else rot_x(math.pi / 2)
    at = translate(*centre) @ turn @ translate(0, 0, -0.035)
    mb.cylinder(0.1, 0.008, frame, at, segments=24)
    mb.cylinder(0.085, 0.054, filament, at @ translate(0, 0, 0.008), segments=24)
    mb.cylinder(0.1, 0.008, frame, at @ translate(0, 0, 0.062), segments=24)


def _head(mb: MeshBuilder, x: float, y: float, z: float, body: int, frame: int) -> None:
    """Print head: a carriage block with a fan shroud and a nozzle below (z = nozzle tip)."""
    mb.box_between((x - 0.035, y - 0.03, z + 0.012), (x + 0.035, y + 0.035, z + 0.08), body)
    mb.cylinder(0.004, 0.012, frame, translate(x, y, z), radius_top=0.008, segments=8)


def _enclosed(mb: MeshBuilder, params: dict) -> None:
    body, frame, bed, filament = _materials(mb, params)
    glass = mb.material('glass', palette.PRINTER_GLASS)
    w, d, h = params['width'], params['depth'], params['height']
    base_h, top_h, wall = 0.09, 0.04, 0.006
    mb.box_between((-w / 2, -d / 2, 0.0), (w / 2, d / 2, base_h), body)
    mb.box_between((-w / 2, -d / 2, h - top_h), (w / 2, d / 2, h), body)
    for sx in (-1, 1):
        for sy in (-1, 1):
            x, y = sx * (w / 2 - 0.015), sy * (d / 2 - 0.015)
            mb.box_between((x - 0.015, y - 0.015, base_h), (x + 0.015, y + 0.015, h - top_h),
                           frame)
        mb.box_between((sx * w / 2 - wall / 2, -d / 2 + 0.03, base_h),
                       (sx * w / 2 + wall / 2, d / 2 - 0.03, h - top_h), body)
    mb.box_between((-w / 2 + 0.03, d / 2 - wall, base_h), (w / 2 - 0.03, d / 2, h - top_h), body)
    if params['door'] == 'glass':
        mb.box_between((-w / 2 + 0.03, -d / 2, base_h), (w / 2 - 0.03, -d / 2 + wall, h - top_h),
                       glass)
        mb.box_between((w / 2 - 0.06, -d / 2 - 0.02, (base_h + h) / 2 - 0.05),
                       (w / 2 - 0.045, -d / 2, (base_h + h) / 2 + 0.05), frame)
    elif params['door'] == 'swung':  # hinged at the left front edge, opened by 90 degrees
        door_w = w - 0.06
        mb.box_between((-w / 2 + 0.03 - wall, -d / 2 - door_w, base_h),
                       (-w / 2 + 0.03, -d / 2, h - top_h), glass)
    # display on the base front
    mb.box_between((-0.06, -d / 2 - 0.012, 0.015), (0.06, -d / 2, base_h - 0.015),
                   mb.material('display', palette.DISPLAY))
    # bed on a z-stage, CoreXY gantry under the roof
    inner_w, inner_d = w - 0.08, d - 0.10
    bed_side = min(inner_w, inner_d) * 0.8
    bed_z = base_h + 0.02 + params['bed_level'] * (h - top_h - base_h - 0.2)
    mb.box_between((-bed_side / 2, -bed_side / 2, bed_z),
                   (bed_side / 2, bed_side / 2, bed_z + 0.01), bed)
    mb.box_between((-0.03, d / 2 - 0.06, base_h), (0.03, d / 2 - 0.03, h - top_h), frame)
    mb.box_between((-0.02, -bed_side / 2, bed_z - 0.02), (0.02, d / 2 - 0.06, bed_z), frame)
    rail_z = h - top_h - 0.05
    for sx in (-1, 1):
        mb.box_between((sx * (inner_w / 2) - 0.01, -inner_d / 2, rail_z),
                       (sx * (inner_w / 2) + 0.01, inner_d / 2, rail_z + 0.02), frame)
    mb.box_between((-inner_w / 2, -0.01, rail_z), (inner_w / 2, 0.01, rail_z + 0.02), frame)
    _head(mb, 0.0, -0.01, rail_z - 0.07, body, frame)
    if params['spool'] == 'top':
        _spool(mb, (0.0, 0.0, h + 0.1), filament, frame, axis='x')
        mb.box_between((-0.05, -0.01, h), (0.05, 0.01, h + 0.1), frame)
    elif params['spool'] == 'side':
        _spool(mb, (w / 2 + 0.045, 0.0, (base_h + h) / 2), filament, frame, axis='x')
    else:
        _spool(mb, (0.0, d / 2 + 0.045, (base_h + h) / 2), filament, frame, axis='y')


def _bedslinger(mb: MeshBuilder, params: dict) -> None:
    body, frame, bed, filament = _materials(mb, params)
    w, d, h = params['width'], params['depth'], params['height']
    bed_size = params['bed_size']
    # base: two y extrusions with cross members and feet
    for sx in (-1, 1):
        x = sx * 0.1
        mb.box_between((x - 0.01, -d / 2, 0.02), (x + 0.01, d / 2, 0.06), frame)
    for sy in (-1, 1):
        mb.box_between((-0.14, sy * (d / 2 - 0.02) - 0.01, 0.02),
                       (0.14, sy * (d / 2 - 0.02) + 0.01, 0.06), frame)
        for sx in (-1, 1):
            mb.cylinder(0.015, 0.02, body, translate(sx * 0.12, sy * (d / 2 - 0.02), 0.0))
    # sliding bed
    travel = 0.5 * (d - bed_size - 0.02)
    bed_y = params['bed_travel'] * travel
    mb.box_between((-bed_size / 2, bed_y - bed_size / 2, 0.07),
                   (bed_size / 2, bed_y + bed_size / 2, 0.08), bed)
    mb.box_between((-0.08, bed_y - 0.08, 0.06), (0.08, bed_y + 0.08, 0.07), frame)
    # z frame across x, gantry, head
    half = w / 2 - 0.06
    for sx in (-1, 1):
        mb.box_between((sx * half - 0.01, 0.02, 0.02), (sx * half + 0.01, 0.06, h - 0.02), frame)
        mb.box_between((sx * half - 0.05, 0.0, 0.0), (sx * half + 0.03 * sx, 0.08, 0.02), body)
        mb.cylinder(0.004, h - 0.2, frame, translate(sx * (half - 0.035), 0.04, 0.1), segments=8)
        mb.box_between((sx * (half + 0.02) - 0.03, 0.02, 0.02),
                       (sx * (half + 0.02) + 0.03, 0.07, 0.08), body)
    mb.box_between((-half - 0.01, 0.02, h - 0.02), (half + 0.01, 0.06, h), frame)
    gantry_z = 0.12 + params['gantry_level'] * (h - 0.25)
    mb.box_between((-half, 0.0, gantry_z), (half, 0.02, gantry_z + 0.04), body)
    head_x = params['head_travel'] * (half - 0.08)
    _head(mb, head_x, -0.03, gantry_z - 0.03, body, frame)
    # control box with display at the front right, power supply at the back
    mb.box_between((w / 2 - 0.16, -d / 2 - 0.01, 0.02), (w / 2 - 0.02, -d / 2 + 0.06, 0.1), body)
    mb.box_between((-w / 2 + 0.02, 0.06, 0.02), (-w / 2 + 0.09, 0.2, 0.16), body)
    if params['spool'] == 'top':
        mb.box_between((-0.01, 0.03, h), (0.01, 0.05, h + 0.11), frame)
        _spool(mb, (0.0, 0.04, h + 0.11), filament, frame, axis='y')
    elif params['spool'] == 'side':
        _spool(mb, (w / 2 + 0.02, 0.04, h - 0.12), filament, frame, axis='x')
    else:
        _spool(mb, (0.0, d / 2 + 0.02, 0.12), filament, frame, axis='y')


def _delta(mb: MeshBuilder, params: dict) -> None:
    body, frame, bed, filament = _materials(mb, params)
    side, h = params['side'], params['height']
    radius = side / math.sqrt(3)  # circumradius of the triangle
    # towers at angles 90 (back, +y), 210 and 330 degrees (the two front corners)
    angles = [math.radians(a) for a in (90.0, 210.0, 330.0)]
    corners = [(radius * math.cos(a), radius * math.sin(a)) for a in angles]
    outline = []
    for a in angles:  # a hexagon: the triangle with its corners cut off
        for da in (-0.18, 0.18):
            outline.append((1.05 * radius * math.cos(a + da), 1.05 * radius * math.sin(a + da)))
    base_h, top_h = 0.09, 0.05
    mb.prism(outline, base_h, body)
    mb.prism(outline, top_h, body, translate(0, 0, h - top_h))
    for (cx, cy), a in zip(corners, angles):
        mb.box((0.03, 0.04, h - base_h - top_h), frame,
               translate(cx, cy, (h + base_h - top_h) / 2) @ rot_z(a))
    bed_r = 0.45 * radius
    mb.cylinder(bed_r, 0.008, bed, translate(0, 0, base_h), segments=32)
    ex, ey, ez = params['effector']
    effector = (ex * bed_r, ey * bed_r, base_h + 0.03 + ez * (h - base_h - top_h - 0.4))
    mb.cylinder(0.035, 0.02, body, translate(*effector), segments=12)
    rod = 0.95 * radius + 0.12
    for (cx, cy), a in zip(corners, angles):
        inward = (-math.cos(a), -math.sin(a))
        carriage_xy = (cx + 0.03 * inward[0], cy + 0.03 * inward[1])
        flat = math.hypot(carriage_xy[0] - effector[0], carriage_xy[1] - effector[1])
        carriage_z = effector[2] + math.sqrt(max(rod**2 - flat**2, 0.01))
        mb.box((0.05, 0.03, 0.05), frame,
               translate(carriage_xy[0], carriage_xy[1], carriage_z) @ rot_z(a))
        along = (-math.sin(a), math.cos(a))
        for s in (-1, 1):
            top = (carriage_xy[0] + s * 0.02 * along[0], carriage_xy[1] + s * 0.02 * along[1],
                   carriage_z)
            low = (effector[0] + s * 0.02 * along[0] - 0.025 * inward[0],
                   effector[1] + s * 0.02 * along[1] - 0.025 * inward[1], effector[2] + 0.01)
            mb.rod(low, top, 0.003, frame, segments=6)
    mb.box_between((-0.05, -radius / 2 - 0.02, 0.015), (0.05, -radius / 2 + 0.01, base_h - 0.02),
                   frame)
    if params['spool'] == 'top':
        mb.box_between((-0.01, -0.01, h), (0.01, 0.01, h + 0.11), frame)
        _spool(mb, (0.0, 0.0, h + 0.11), filament, frame, axis='x')
    elif params['spool'] == 'side':
        cx, cy = corners[2]
        _spool(mb, (cx + 0.06, cy, h * 0.6), filament, frame, axis='x')
    else:
        cx, cy = corners[0]
        _spool(mb, (cx, cy + 0.06, h * 0.6), filament, frame, axis='y')


def _largeformat(mb: MeshBuilder, params: dict) -> None:
    body, frame, bed, filament = _materials(mb, params)
    w, d, h = params['width'], params['depth'], params['height']
    e = 0.02  # half width of a 40 mm extrusion
    base_h = 0.14 if params['frame'] == 'cabinet' else 0.0
    if base_h:
        mb.box_between((-w / 2, -d / 2, 0.0), (w / 2, d / 2, base_h), body)
        mb.box_between((-0.1, -d / 2 - 0.015, 0.03), (0.1, -d / 2, base_h - 0.03), frame)
    _extrusion_cube(mb, w, d, base_h, h, e, frame)
    xs, ys = (-w / 2 + e, w / 2 - e), (-d / 2 + e, d / 2 - e)
    if params['frame'] == 'cabinet':
        glass = mb.material('panel', (60, 66, 72))
        for sx in (-1, 1):
            mb.box_between((sx * w / 2 - 0.003, ys[0], base_h), (sx * w / 2 + 0.003, ys[1], h),
                           glass)
        mb.box_between((xs[0], d / 2 - 0.006, base_h), (xs[1], d / 2, h), glass)
    # bed on two z lead screws at the back, gantry at the top, head
    bed_w, bed_d = w - 0.16, d - 0.2
    bed_z = base_h + 0.06 + params['bed_level'] * (h - base_h - 0.3)
    mb.box_between((-bed_w / 2, -bed_d / 2, bed_z), (bed_w / 2, bed_d / 2, bed_z + 0.012), bed)
    for sx in (-1, 1):
        mb.box_between((sx * bed_w / 4 - 0.015, -bed_d / 2, bed_z - 0.03),
                       (sx * bed_w / 4 + 0.015, d / 2 - 2 * e, bed_z), frame)
        mb.cylinder(
            0.006,
            h - base_h - 2 * e,
            frame,
            translate(sx * bed_w / 4, d / 2 - 3 * e, base_h + e),
            segments=8)
    gantry_z = h - 2 * e - 0.05
    for sx in (-1, 1):
        mb.box_between((sx * (w / 2 - 3 * e) - 0.015, ys[0], gantry_z),
                       (sx * (w / 2 - 3 * e) + 0.015, ys[1], gantry_z + 0.03), frame)
    head_x = params['head_travel'] * (w / 2 - 0.12)
    mb.box_between((xs[0] + e, -0.015, gantry_z), (xs[1] - e, 0.015, gantry_z + 0.03), body)
    _head(mb, head_x, -0.02, gantry_z - 0.08, body, frame)
    # control box with display on the front right post
    mb.box_between((w / 2 - 0.2, -d / 2 - 0.04, base_h + 0.05),
                   (w / 2 - 0.05, -d / 2, base_h + 0.15), body)
    for k in range(2 if params['spool'] != 'top' else 1):
        if params['spool'] == 'top':
            mb.box_between((-0.01, -0.01, h), (0.01, 0.01, h + 0.11), frame)
            _spool(mb, (0.0, 0.0, h + 0.11), filament, frame, axis='x')
        elif params['spool'] == 'side':
            _spool(mb, (-w / 2 - 0.045, (k - 0.5) * 0.25, h * 0.65), filament, frame, axis='x')
        else:
            _spool(mb, ((k - 0.5) * 0.25, d / 2 + 0.045, h * 0.65), filament, frame, axis='y')


def _extrusion_cube(mb: MeshBuilder, w: float, d: float, z0: float, h: float, e: float,
                    frame: int) -> None:
    """The 12 edges of a box frame of square extrusions (half width e) from z0 to h."""
    xs, ys = (-w / 2 + e, w / 2 - e), (-d / 2 + e, d / 2 - e)
    for x in xs:
        for y in ys:
            mb.box_between((x - e, y - e, z0), (x + e, y + e, h), frame)
    for z in (z0 + e, h - e):
        for y in ys:
            mb.box_between((xs[0], y - e, z - e), (xs[1], y + e, z + e), frame)
        for x in xs:
            mb.box_between((x - e, ys[0], z - e), (x + e, ys[1], z + e), frame)


def _corexy(mb: MeshBuilder, params: dict) -> None:
    """Open 2020-extrusion cube: bed on a z stage, XY gantry under the top frame, electronics
    under a bottom panel, spool on the back."""
    body, frame, bed, filament = _materials(mb, params)
    w, d, h = params['width'], params['depth'], params['height']
    e = 0.01
    _extrusion_cube(mb, w, d, 0.0, h, e, frame)
    mb.box_between((-w / 2 + 2 * e, -d / 2 + 2 * e, 0.05), (w / 2 - 2 * e, d / 2 - 2 * e, 0.056),
                   body)
    bed_side = min(w, d) - 0.12
    bed_z = 0.08 + params['bed_level'] * (h - 0.25)
    mb.box_between((-bed_side / 2, -bed_side / 2, bed_z),
                   (bed_side / 2, bed_side / 2, bed_z + 0.012), bed)
    for sx in (-1, 1):  # bed carriers on the back z rails
        mb.box_between((sx * bed_side / 3 - 0.01, -bed_side / 2, bed_z - 0.025),
                       (sx * bed_side / 3 + 0.01, d / 2 - 2 * e, bed_z), frame)
        mb.box_between((sx * bed_side / 3 - 0.008, d / 2 - 2 * e - 0.016, 2 * e),
                       (sx * bed_side / 3 + 0.008, d / 2 - 2 * e, h - 2 * e), frame)
    gantry_z = h - 0.07
    head_x, head_y = (params['head'][0] * (w / 2 - 0.08), params['head'][1] * (d / 2 - 0.08))
    for sx in (-1, 1):
        mb.box_between((sx * (w / 2 - 0.035) - 0.01, -d / 2 + 2 * e, gantry_z),
                       (sx * (w / 2 - 0.035) + 0.01, d / 2 - 2 * e, gantry_z + 0.02), frame)
    mb.box_between((-w / 2 + 0.045, head_y - 0.01, gantry_z),
                   (w / 2 - 0.045, head_y + 0.01, gantry_z + 0.02), frame)
    _head(mb, head_x, head_y - 0.03, gantry_z - 0.07, body, frame)
    mb.box_between((-0.06, -d / 2 - 0.015, 0.01), (0.06, -d / 2, 0.045), body)  # display
    _spool(mb, (0.0, d / 2 + 0.045, h * 0.55), filament, frame, axis='y')


def _resin(mb: MeshBuilder, params: dict) -> None:
    """Base with the light engine and a display, a translucent colored lid over the vat: a
    box (MSLA) or a sloped hinged lid (SLA), the z tower inside."""
    body, frame, _, _ = _materials(mb, params)
    lid = mb.material('lid', params['lid_color'])
    w, d, h = params['width'], params['depth'], params['height']
    base_h = round(params['base_fraction'] * h, 4)
    mb.box_between((-w / 2, -d / 2, 0.0), (w / 2, d / 2, base_h), body)
    mb.box_between((-0.045, -d / 2 - 0.01, base_h * 0.3), (0.045, -d / 2, base_h * 0.8), frame)
    mb.box_between((-w / 4, -d / 4, base_h), (w / 4, d / 4, base_h + 0.03), frame)  # vat
    if params['lid_style'] == 'box':
        mb.box_between((-w / 2 + 0.01, -d / 2 + 0.01, base_h), (w / 2 - 0.01, d / 2 - 0.01, h),
                       lid)
        return
    # hinged lid: full height at the back, sloping down towards the front
    front_h = base_h + 0.55 * (h - base_h)
    outline = [(-d / 2 + 0.01, base_h), (d / 2 - 0.01, base_h), (d / 2 - 0.01, h),
               (d / 2 - 0.12, h), (-d / 2 + 0.01, front_h)]
    # the outline lies in the y/z plane: this frame maps local x, y, z to world y, z, x
    from_side = translate(-w / 2 + 0.01, 0, 0) @ rot_y(math.pi / 2) @ rot_z(math.pi / 2)
    mb.prism(outline, w - 0.02, lid, from_side)


def _cantilever(mb: MeshBuilder, params: dict) -> None:
    """Compact bed-slinger: a y rail with the sliding bed, one z column at the side and an x arm
    carrying the head over the bed."""
    body, frame, bed, filament = _materials(mb, params)
    w, d, h = params['width'], params['depth'], params['height']
    side = params['column_side']
    bed_size = 0.18
    mb.box_between((-w / 2 + 0.02, -d / 2, 0.0), (w / 2 - 0.02, d / 2 - 0.03, 0.025), body)
    mb.box_between((-0.05, -d / 2, 0.025), (0.05, d / 2, 0.05), frame)
    travel = 0.5 * (d - bed_size - 0.02)
    bed_y = params['bed_travel'] * travel
    mb.box_between((-bed_size / 2, bed_y - bed_size / 2, 0.06),
                   (bed_size / 2, bed_y + bed_size / 2, 0.07), bed)
    mb.box_between((-0.04, bed_y - 0.04, 0.05), (0.04, bed_y + 0.04, 0.06), frame)
    x_col = side * (w / 2 - 0.03)
    mb.box_between((x_col - 0.03, -0.05, 0.025), (x_col + 0.03, 0.06, 0.06), body)  # foot
    mb.box_between((x_col - 0.02, -0.02, 0.06), (x_col + 0.02, 0.03, h), frame)
    arm_z = 0.12 + params['gantry_level'] * (h - 0.2)
    mb.box_between((min(x_col, -side * (bed_size / 2 + 0.04)), -0.02, arm_z),
                   (max(x_col, -side * (bed_size / 2 + 0.04)), 0.0, arm_z + 0.03), frame)
    head_x = params['head_travel'] * (bed_size / 2 - 0.01)
    _head(mb, head_x, -0.045, arm_z - 0.04, body, frame)
    # display box at the front corner of the base, spool holder on top of the column
    x_display = -side * (w / 2 - 0.08)
    mb.box_between((x_display - 0.05, -d / 2 - 0.01, 0.025),
                   (x_display + 0.05, -d / 2 + 0.05, 0.07), body)
    _spool(mb, (x_col, 0.005, h - 0.09), filament, frame, axis='x')


def _boxframe(mb: MeshBuilder, params: dict) -> None:
    """Ultimaker-style box: closed sides, back and roof, open (or glass) front, a bed on a z
    stage, cross-rod gantry, spool holder on the back, display in the base."""
    body, frame, bed, filament = _materials(mb, params)
    glass = mb.material('glass', palette.PRINTER_GLASS)
    w, d, h = params['width'], params['depth'], params['height']
    base_h, wall = 0.06, 0.01
    mb.box_between((-w / 2, -d / 2, 0.0), (w / 2, d / 2, base_h), body)
    for sx in (-1, 1):
        mb.box_between((sx * w / 2 - wall / 2 - sx * wall / 2, -d / 2, base_h),
                       (sx * w / 2 + wall / 2 - sx * wall / 2, d / 2, h), body)
    mb.box_between((-w / 2 + wall, d / 2 - wall, base_h), (w / 2 - wall, d / 2, h), body)
    mb.box_between((-w / 2 + wall, -d / 2, h - 0.03), (w / 2 - wall, d / 2 - wall, h - 0.02),
                   frame)
    mb.box_between((-0.05, -d / 2 - 0.008, 0.01), (0.05, -d / 2, base_h - 0.01),
                   mb.material('display', palette.DISPLAY))  # display
    if params['door'] == 'glass':
        mb.box_between((-w / 2 + wall, -d / 2, base_h), (w / 2 - wall, -d / 2 + 0.005, h - 0.03),
                       glass)
    bed_w, bed_d = w - 0.1, d - 0.14
    bed_z = base_h + 0.03 + params['bed_level'] * (h - base_h - 0.2)
    mb.box_between((-bed_w / 2, -bed_d / 2, bed_z), (bed_w / 2, bed_d / 2, bed_z + 0.01), bed)
    for sx in (-1, 1):
        mb.cylinder(
            0.006,
            h - base_h - 0.03,
            frame,
            translate(sx * 0.08, d / 2 - 0.04, base_h),
            segments=8)
    mb.box_between((-0.1, -bed_d / 2, bed_z - 0.02), (0.1, d / 2 - wall, bed_z), frame)
    rod_z = h - 0.08
    head_x, head_y = (params['head'][0] * (w / 2 - 0.07), params['head'][1] * (d / 2 - 0.07))
    mb.rod((-w / 2 + wall, head_y, rod_z), (w / 2 - wall, head_y, rod_z), 0.004, frame, segments=8)
    mb.rod((head_x, -d / 2 + 0.02, rod_z), (head_x, d / 2 - wall, rod_z), 0.004, frame, segments=8)
    _head(mb, head_x, head_y, rod_z - 0.07, body, frame)
    _spool(mb, (0.0, d / 2 + 0.045, h * 0.55), filament, frame, axis='y')
