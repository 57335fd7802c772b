"""Factory clutter: shelves, cabinets, machines, pallets, crates, carts, bins and pipe runs.

Pure numpy. :func:`sample_clutter` and :func:`sample_pipe_run` draw one clutter object as an
:class:`~generator.asset_spec.AssetSpec` of class ``clutter``: its kind, size and parameters (style,
colors, counts), all listed in ``meta.json``. :func:`clutter_mesh` builds its triangles from the
spec alone: closed solids (boxes and axis-aligned cylinders) in the asset's local frame (xy
centred, z = 0 at the bottom, front towards -y, back towards +y) whose bounds are exactly the
spec's size.

Some are built to look like the detection classes: a low cabinet with a worktop as high as a
table, a crate as big as a 3D printer (the layout puts such crates on tables), a shelf cart like
a small table. ``box`` and ``cylinder`` are the plain primitives of the earlier light clutter.
"""
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from generator.asset_spec import AssetSpec
from generator.assets import palette

PRIMITIVE_KINDS = ('box', 'cylinder')
FACTORY_KINDS = ('shelf', 'cabinet', 'machine', 'pallet', 'crate', 'cart', 'bin', 'pipe')
CLUTTER_KINDS = PRIMITIVE_KINDS + FACTORY_KINDS
WALL_KINDS = ('shelf', 'cabinet', 'machine')  # stand with their back to a wall
PALLET_HEIGHT = 0.144  # EUR pallet: three 22 mm board layers on 78 mm blocks

Size = tuple[float, float, float]

# two triangles per face of the box with corners 0-3 at the bottom and 4-7 above them, outwards
_BOX_TRIANGLES = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
                           [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]],
                          dtype=np.int32)


class ColoredSolids:
    """Collects closed, outward-wound solids with one color each."""

    def __init__(self) -> None:
        self.vertices: list[np.ndarray] = []
        self.triangles: list[np.ndarray] = []
        self.colors: list[np.ndarray] = []
        self.count = 0

    def _add(self, vertices: np.ndarray, triangles: np.ndarray, rgb: Sequence[int]) -> None:
        self.vertices.append(vertices)
        self.triangles.append(triangles + self.count)
        self.colors.append(np.tile(np.asarray(rgb, dtype=np.uint8), (len(triangles), 1)))
        self.count += len(vertices)

    def box(self, lo: Sequence[float], hi: Sequence[float], rgb: Sequence[int]) -> None:
        """Axis-aligned box from corner ``lo`` to corner ``hi``."""
        (x0, y0, z0), (x1, y1, z1) = lo, hi
        if not (x0 < x1 and y0 < y1 and z0 < z1):
            raise ValueError(f'empty box {lo} -> {hi}')
        self._add(
            np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0], [x0, y0, z1],
                      [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]],
                     dtype=float), _BOX_TRIANGLES, rgb)

    def cylinder(self,
                 base: Sequence[float],
                 axis: int,
                 radius: float,
                 length: float,
                 rgb: Sequence[int],
                 segments: int = 16) -> None:
        """Capped cylinder along coordinate ``axis`` from ``base`` over ``length``; with
        ``segments`` a multiple of 4 it reaches exactly ``radius`` along the two other axes."""
        u, w = (axis + 1) % 3, (axis + 2) % 3
        angles = np.arange(segments) * 2 * np.pi / segments
        bottom = np.tile(np.asarray(base, dtype=float), (segments, 1))
        bottom[:, u] += np.cos(angles) * radius
        bottom[:, w] += np.sin(angles) * radius
        top = bottom.copy()
        top[:, axis] += length
        caps = np.array([base, base], dtype=float)
        caps[1, axis] += length
        i = np.arange(segments)
        j = (i + 1) % segments
        cb, ct = 2 * segments, 2 * segments + 1
        triangles = np.concatenate([
            np.stack([i, j, j + segments], 1),
            np.stack([i, j + segments, i + segments], 1),
            np.stack([np.full(segments, cb), j, i], 1),
            np.stack([np.full(segments, ct), i + segments, j + segments], 1)
        ]).astype(np.int32)
        self._add(np.concatenate([bottom, top, caps]), triangles, rgb)

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return (np.concatenate(self.vertices), np.concatenate(self.triangles),
                np.concatenate(self.colors))


# ----------------------------------------------------------------------------- sampling


def _mm(value: float) -> float:
    return round(float(value), 3)


def _color(rng: np.random.Generator, options: Sequence[Sequence[int]]) -> list[int]:
    return [int(c) for c in options[int(rng.integers(len(options)))]]


def _height(rng: np.random.Generator, low: float, high: float, max_height: float) -> float:
    """A height in [low, high], lowered to fit under ``max_height`` (a low room)."""
    high = min(high, max_height)
    return _mm(rng.uniform(low if low <= high else 0.8 * high, high))


def _size(rng, width: Sequence[float], depth: Sequence[float], height: Sequence[float],
          max_height: float) -> Size:
    """Width, depth and height drawn from their ranges, the height under ``max_height``."""
    return _mm(rng.uniform(*width)), _mm(rng.uniform(*depth)), _height(rng, *height, max_height)


def _shelf(rng, max_height: float) -> tuple[Size, dict]:
    style = 'rack' if rng.random() < 0.5 else 'shelving'
    if style == 'rack':  # pallet rack: colored uprights and beams
        size = _size(rng, (1.8, 2.7), (0.8, 1.1), (1.8, 2.6), max_height)
        frame, board = _color(rng, palette.INDUSTRIAL[1:5]), _color(rng, palette.WOOD)
    else:  # boltless shelving: grey posts, steel or chipboard boards
        size = _size(rng, (0.8, 1.5), (0.35, 0.6), (1.5, 2.2), max_height)
        frame = _color(rng, palette.METAL)
        board = _color(rng, palette.METAL + palette.WOOD)
    levels = int(rng.integers(2, 4)) if size[2] < 1.2 else int(rng.integers(3, 6))
    return size, {
        'style': style,
        'levels': levels,
        'color': frame,
        'board_color': board,
        'fill': _mm(rng.uniform(0.2, 0.9)),
        'fill_seed': int(rng.integers(2**31))
    }


def _cabinet(rng, max_height: float) -> tuple[Size, dict]:
    style = ('tall', 'low', 'drawers')[int(rng.integers(3))]
    if style == 'tall':
        size = _size(rng, (0.8, 1.2), (0.4, 0.6), (1.6, 2.0), max_height)
    elif style == 'low':  # a sideboard with a worktop as high as a table
        size = _size(rng, (0.8, 1.8), (0.45, 0.65), (0.7, 0.8), max_height)
    else:  # tool cabinet
        size = _size(rng, (0.6, 1.2), (0.45, 0.7), (0.8, 1.1), max_height)
    return size, {
        'style': style,
        'color': _color(rng, palette.INDUSTRIAL + palette.METAL),
        'front_color': _color(rng, palette.INDUSTRIAL),
        'top_color': _color(rng, palette.LAMINATE + palette.WOOD),
        'rows': int(rng.integers(3, 7)) if style == 'drawers' else int(rng.integers(1, 3))
    }


def _machine(rng, max_height: float) -> tuple[Size, dict]:
    size = _size(rng, (1.2, 3.0), (1.0, 2.0), (1.5, 2.3), max_height)
    return size, {
        'style': 'cnc',
        'color': _color(rng, palette.INDUSTRIAL),
        'accent_color': _color(rng, palette.INDUSTRIAL),
        'glass_color': _color(rng, palette.GLASS),
        'panel_side': 1 if rng.random() < 0.5 else -1,
        'tower': bool(rng.random() < 0.6 and size[2] > 1.2)
    }


def _pallet(rng, max_height: float) -> tuple[Size, dict]:
    footprint = ((1.2, 0.8), (1.2, 1.0), (0.8, 0.6))[int(rng.integers(3))]
    loaded = rng.random() < 0.4
    load = _mm(rng.uniform(0.3, min(1.3, max_height - PALLET_HEIGHT))) if loaded else 0.0
    style = 'wood' if rng.random() < 0.75 else 'plastic'
    return (footprint[0], footprint[1], _mm(PALLET_HEIGHT + load)), {
        'style': style,
        'color': _color(rng, palette.WOOD[:3] if style == 'wood' else palette.PLASTIC),
        'load': load,
        'load_color': _color(rng, palette.CARDBOARD + ((225, 228, 230), ))
    }


def _crate(rng, max_height: float, small: bool = False) -> tuple[Size, dict]:
    styles = ('cardboard', 'plastic') if small else ('cardboard', 'plastic', 'wooden')
    style = styles[int(rng.integers(len(styles)))]
    if small:  # as big as a 3D printer
        layers = 1
        size = _size(rng, (0.4, 0.65), (0.38, 0.6), (0.4, 0.7), max_height)
    elif style == 'cardboard':
        layers = int(rng.integers(1, 4))
        size = (_mm(rng.uniform(0.3, 0.8)), _mm(rng.uniform(0.25, 0.6)),
                _height(rng, 0.2 * layers, 0.5 * layers, max_height))
    elif style == 'plastic':  # Euro containers, 600 x 400 or 400 x 300, stacked
        layers = int(rng.integers(1, 5))
        width, depth = ((0.6, 0.4), (0.4, 0.3))[int(rng.integers(2))]
        size = (width, depth, _height(rng, 0.12 * layers, 0.32 * layers, max_height))
    else:
        layers = 1
        size = _size(rng, (0.6, 1.2), (0.5, 1.0), (0.4, 1.0), max_height)
    colors = {'cardboard': palette.CARDBOARD, 'plastic': palette.PLASTIC, 'wooden': palette.WOOD}
    return size, {'style': style, 'layers': layers, 'color': _color(rng, colors[style])}


def _cart(rng, max_height: float) -> tuple[Size, dict]:
    style = 'shelf' if rng.random() < 0.5 else 'platform'
    if style == 'shelf':  # like a small table: the top shelf at table height
        size = _size(rng, (0.8, 1.1), (0.5, 0.7), (0.75, 0.95), max_height)
    else:
        size = _size(rng, (0.8, 1.3), (0.5, 0.8), (0.85, 1.05), max_height)
    return size, {
        'style': style,
        'shelves': int(rng.integers(2, 4)) if style == 'shelf' else 1,
        'wheel_radius': _mm(rng.uniform(0.05, 0.08)),
        'color': _color(rng, palette.METAL + palette.INDUSTRIAL[1:5]),
        'deck_color': _color(rng, palette.PLASTIC + palette.WOOD[:2])
    }


def _bin(rng, max_height: float) -> tuple[Size, dict]:
    style = ('drum', 'wheelie', 'cage')[int(rng.integers(3))]
    if style == 'drum':
        diameter = _mm(rng.uniform(0.4, 0.6))
        size = (diameter, diameter, _height(rng, 0.5, 0.9, max_height))
        color = _color(rng, palette.INDUSTRIAL + palette.PLASTIC)
    elif style == 'wheelie':
        size = _size(rng, (0.48, 0.6), (0.55, 0.75), (0.95, 1.07), max_height)
        color = _color(rng, palette.PLASTIC)
    else:  # mesh pallet cage
        size = _size(rng, (0.8, 1.24), (0.6, 0.84), (0.7, 0.97), max_height)
        color = _color(rng, palette.METAL[1:4])
    return size, {'style': style, 'color': color}


_SAMPLERS: dict[str, Callable[..., tuple[Size, dict]]] = {
    'shelf': _shelf,
    'cabinet': _cabinet,
    'machine': _machine,
    'pallet': _pallet,
    'crate': _crate,
    'cart': _cart,
    'bin': _bin
}


def _spec(kind: str, size: Size, params: dict):
    top = None
    if kind == 'pallet' and params['load'] == 0:  # an empty pallet carries crates
        top = (size[2], (size[0], size[1]))
    return AssetSpec('clutter', f'clutter/{kind}', f'clutter/{kind}', {
        'kind': kind,
        **params
    }, size, None if top is None else top[0], None if top is None else top[1])


def sample_clutter(rng: np.random.Generator, kind: str, max_height: float, small: bool = False):
    """Draw one clutter object of ``kind`` (not a pipe) at most ``max_height`` high;
    ``small``: a crate as big as a 3D printer, for a table top."""
    if kind == 'crate':
        size, params = _crate(rng, max_height, small)
    else:
        size, params = _SAMPLERS[kind](rng, max_height)
    return _spec(kind, size, params)


def sample_pipe_run(rng: np.random.Generator, length: float, mount: str, max_height: float):
    """Draw a run of 1-3 parallel pipes ``length`` long, mounted on a ``'wall'`` (stacked,
    brackets towards +y) or hung from the ``'ceiling'`` (side by side, hangers up to its top;
    pipes and hangers at most ``max_height`` high)."""
    pipes = int(rng.integers(1, 4))
    diameter = _mm(rng.uniform(0.06, 0.25 if pipes == 1 else 0.16))
    gap = _mm(rng.uniform(0.03, 0.1))
    bundle = pipes * diameter + (pipes - 1) * gap
    if mount == 'wall':
        size = (_mm(length), _mm(diameter + rng.uniform(0.03, 0.12)), _mm(bundle))
    else:
        drop = min(rng.uniform(0.15, 0.6), max_height - diameter)
        size = (_mm(length), _mm(bundle), _mm(diameter + drop))
    return _spec(
        'pipe', size, {
            'mount': mount,
            'pipes': pipes,
            'diameter': diameter,
            'gap': gap,
            'color': _color(rng, palette.PIPE),
            'bracket_color': _color(rng, palette.METAL)
        })


def sample_primitive(rng: np.random.Generator, kind: str, size_range: Sequence[float]):
    """A plain box or cylinder (the earlier light clutter), sides drawn from ``size_range``."""
    sx = _mm(rng.uniform(*size_range))
    sy = sx if kind == 'cylinder' else _mm(rng.uniform(*size_range))
    sz = _mm(rng.uniform(0.2, 1.2))
    color = [int(v) for v in rng.integers(40, 220, size=3)]
    return _spec(kind, (sx, sy, sz), {'color': color})


# ----------------------------------------------------------------------------- meshes


def _build_primitive(s: ColoredSolids, size: Size, p: dict) -> None:
    sx, sy, sz = size
    if p['kind'] == 'box':
        s.box((-sx / 2, -sy / 2, 0), (sx / 2, sy / 2, sz), p['color'])
    else:
        s.cylinder((0, 0, 0), 2, sx / 2, sz, p['color'])


def line_up_items(fill: np.random.Generator, rows: Iterable[tuple[float, float]],
                  x_range: tuple[float, float], width_range: tuple[float, float],
                  gap_range: tuple[float, float], share: float,
                  place: Callable[[float, float, float, float], None]) -> None:
    """Line up items from left to right within ``x_range`` on each (bottom, top) row of a shelf.

    Each item draws its width from ``width_range`` (the row ends where it would pass the
    range), stands with chance ``share`` where the row is more than 0.1 m high, drawn by
    ``place(x, width, bottom, top)``, and leaves a gap drawn from ``gap_range``.
    """
    x_start, x_end = x_range
    for z0, z1 in rows:
        x = x_start
        while True:
            width = fill.uniform(*width_range)
            if x + width > x_end:
                break
            if fill.random() < share and z1 - z0 > 0.1:
                place(x, width, z0, z1)
            x += width + fill.uniform(*gap_range)


def _build_shelf(s: ColoredSolids, size: Size, p: dict) -> None:
    w, d, h = size
    post, board = (0.07, 0.03) if p['style'] == 'rack' else (0.035, 0.02)
    for x in (-w / 2, w / 2 - post):
        for y in (-d / 2, d / 2 - post):
            s.box((x, y, 0), (x + post, y + post, h), p['color'])
    levels = np.linspace(0.1, h - board, p['levels'])
    for z in levels:
        s.box((-w / 2, -d / 2, z), (w / 2, d / 2, z + board), p['board_color'])
        if p['style'] == 'rack' and z >= 0.09:  # beams under the boards, front and back
            for y in (-d / 2, d / 2 - 0.05):
                s.box((-w / 2 + post, y, z - 0.09), (w / 2 - post, y + 0.05, z), p['color'])
    fill = np.random.default_rng(p['fill_seed'])  # goods on the shelves, fixed by the spec

    def goods(x: float, width: float, z0: float, z1: float) -> None:
        depth = fill.uniform(0.5, 0.95) * d
        height = fill.uniform(0.3, 0.85) * (z1 - z0 - 0.02)
        s.box((x, -d / 2 + 0.01, z0), (x + width, -d / 2 + 0.01 + depth, z0 + height),
              _color(fill, palette.CARDBOARD + palette.PLASTIC))

    rows = zip(levels[:-1] + board, levels[1:] - (0.09 if p['style'] == 'rack' else 0))
    line_up_items(fill, rows, (-w / 2 + post + 0.02, w / 2 - post - 0.02), (0.15, 0.5),
                  (0.01, 0.1), p['fill'], goods)


def _build_cabinet(s: ColoredSolids, size: Size, p: dict) -> None:
    w, d, h = size
    plinth, worktop = 0.06, (0.03 if p['style'] == 'low' else 0.0)
    handle_y, front_y, body_y = -d / 2, -d / 2 + 0.025, -d / 2 + 0.045
    top = h - worktop
    s.box((-w / 2 + 0.03, body_y + 0.03, 0), (w / 2 - 0.03, d / 2 - 0.03, plinth), p['color'])
    s.box((-w / 2, body_y, plinth), (w / 2, d / 2, top), p['color'])
    if worktop:
        s.box((-w / 2, -d / 2, top), (w / 2, d / 2, h), p['top_color'])
    columns = 1 if p['style'] == 'drawers' or w < 0.7 else 2
    rows = p['rows']
    xs, zs = np.linspace(-w / 2, w / 2, columns + 1), np.linspace(plinth, top, rows + 1)
    for c in range(columns):
        for r in range(rows):
            x0, x1, z0, z1 = xs[c] + 0.004, xs[c + 1] - 0.004, zs[r] + 0.004, zs[r + 1] - 0.004
            s.box((x0, front_y, z0), (x1, body_y, z1), p['front_color'])
            if p['style'] == 'drawers' or rows > columns:  # a bar at the top of a drawer
                xc, zc, half = (x0 + x1) / 2, z1 - 0.04, (0.08, 0.008)
            else:  # a vertical bar next to the doors' meeting edge
                xc = x1 - 0.05 if c == 0 and columns == 2 else x0 + 0.05
                zc, half = (z0 + z1) / 2, (0.008, 0.08)
            s.box((xc - half[0], handle_y, zc - half[1]), (xc + half[0], front_y, zc + half[1]),
                  palette.METAL[2])


def _build_machine(s: ColoredSolids, size: Size, p: dict) -> None:
    w, d, h = size
    tower = 0.3 if p['tower'] else 0.0
    body = h - tower
    front = -d / 2 + 0.2  # the control panel stands out 20 cm in front of the body
    recess = 0.08
    s.box((-w / 2 + 0.05, front + 0.05, 0), (w / 2 - 0.05, d / 2 - 0.05, 0.1), palette.METAL[4])
    s.box((-w / 2, front + recess, 0.1), (w / 2, d / 2, body), p['color'])
    # the front door: a frame around a window set back in the recess
    a, b = -w / 2 + 0.15 * w, w / 2 - 0.15 * w
    z0, z1 = 0.1 + 0.45 * (body - 0.1), body - 0.12 * (body - 0.1)
    for lo, hi in (((-w / 2, front, 0.1),
                    (a, front + recess, body)), ((b, front, 0.1), (w / 2, front + recess, body)),
                   ((a, front, 0.1), (b, front + recess, z0)), ((a, front, z1), (b, front + recess,
                                                                                 body))):
        s.box(lo, hi, p['accent_color'])
    s.box((a, front + recess - 0.02, z0), (b, front + recess, z1), p['glass_color'])
    panel_w = min(0.45, 0.3 * w)
    x0 = w / 2 - panel_w if p['panel_side'] > 0 else -w / 2
    pz0 = 0.5 * body
    s.box((x0, -d / 2, pz0), (x0 + panel_w, front, min(pz0 + 0.5, body)), palette.PLASTIC[0])
    if tower:  # signal tower: a pole and red, amber and green lights
        base = np.array([p['panel_side'] * -(w / 2 - 0.1), d / 2 - 0.1, body])
        s.cylinder(base, 2, 0.015, 0.06, palette.METAL[2], segments=8)
        for k, rgb in enumerate(((200, 30, 30), (240, 170, 0), (40, 170, 60))):
            s.cylinder(base + [0, 0, 0.06 + 0.08 * k], 2, 0.04, 0.08, rgb)


def _build_pallet(s: ColoredSolids, size: Size, p: dict) -> None:
    w, d, _ = size
    t, block = 0.022, 0.078
    xs = (-w / 2, -0.0725, w / 2 - 0.145)
    for y in (-d / 2, -0.05, d / 2 - 0.1):  # bottom boards along x
        s.box((-w / 2, y, 0), (w / 2, y + 0.1, t), p['color'])
    for x in xs:
        for y in (-d / 2, -0.05, d / 2 - 0.1):
            s.box((x, y, t), (x + 0.145, y + 0.1, t + block), p['color'])
        s.box((x, -d / 2, t + block), (x + 0.145, d / 2, 2 * t + block), p['color'])
    for y in np.linspace(-d / 2, d / 2 - 0.1, 5):  # top deck
        s.box((-w / 2, y, 2 * t + block), (w / 2, y + 0.1, PALLET_HEIGHT), p['color'])
    if p['load'] > 0:  # wrapped goods
        s.box((-w / 2 + 0.02, -d / 2 + 0.02, PALLET_HEIGHT),
              (w / 2 - 0.02, d / 2 - 0.02, PALLET_HEIGHT + p['load']), p['load_color'])


def _build_crate(s: ColoredSolids, size: Size, p: dict) -> None:
    w, d, h = size
    step = h / p['layers']
    for k in range(p['layers']):
        z0, z1 = k * step, (k + 1) * step
        if p['style'] == 'cardboard':  # a box closed by a tape strip
            s.box((-w / 2, -d / 2, z0), (w / 2, d / 2, z1 - 0.002), p['color'])
            s.box((-0.025, -d / 2, z1 - 0.002), (0.025, d / 2, z1), (200, 190, 160))
        elif p['style'] == 'plastic':  # tapered container under a rim
            rim = min(0.03, step / 3)
            s.box((-w / 2 + 0.015, -d / 2 + 0.015, z0), (w / 2 - 0.015, d / 2 - 0.015, z1 - rim),
                  p['color'])
            s.box((-w / 2, -d / 2, z1 - rim), (w / 2, d / 2, z1), p['color'])
        else:  # a wooden core behind three bands of boards
            s.box((-w / 2 + 0.015, -d / 2 + 0.015, z0), (w / 2 - 0.015, d / 2 - 0.015, z1),
                  p['color'])
            for zb in (z0, (z0 + z1) / 2 - 0.04, z1 - 0.08):
                s.box((-w / 2, -d / 2, zb), (w / 2, d / 2, zb + 0.08), palette.WOOD[1])


def _build_cart(s: ColoredSolids, size: Size, p: dict) -> None:
    w, d, h = size
    r, rod = p['wheel_radius'], 0.0125
    deck = 2 * r + 0.03
    for x in (-w / 2 + 0.1, w / 2 - 0.1):
        for y in (-d / 2 + 0.06, d / 2 - 0.06):
            s.cylinder((x, y - 0.0175, r), 1, r, 0.035, palette.PLASTIC[0])
            s.box((x - 0.025, y - 0.025, r), (x + 0.025, y + 0.025, deck), p['color'])
    x0 = -w / 2 + 2 * rod  # the handle stands at the -x end
    if p['style'] == 'shelf':
        for z in np.linspace(deck, h - 0.03, p['shelves']):
            s.box((x0, -d / 2, z), (w / 2, d / 2, z + 0.03), p['deck_color'])
        for x in (x0, w / 2 - 0.025):
            for y in (-d / 2, d / 2 - 0.025):
                s.box((x, y, deck), (x + 0.025, y + 0.025, h - 0.03), p['color'])
    else:
        s.box((x0, -d / 2, deck), (w / 2, d / 2, deck + 0.04), p['deck_color'])
    xh, half = -w / 2 + rod, d / 2 - 0.06
    for y in (-half, half):
        s.cylinder((xh, y, deck), 2, rod, h - rod - deck, p['color'])
    s.cylinder((xh, -half - rod, h - rod), 1, rod, 2 * (half + rod), p['color'])


def _build_bin(s: ColoredSolids, size: Size, p: dict) -> None:
    w, d, h = size
    if p['style'] == 'drum':
        s.cylinder((0, 0, 0), 2, w / 2 - 0.01, h, p['color'], segments=24)
        for z in (0.0, h / 3 - 0.01, 2 * h / 3 - 0.01, h - 0.02):
            s.cylinder((0, 0, z), 2, w / 2, 0.02, p['color'], segments=24)
    elif p['style'] == 'wheelie':
        s.box((-w / 2 + 0.02, -d / 2 + 0.03, 0.03), (w / 2 - 0.02, d / 2 - 0.08, h - 0.04),
              p['color'])
        s.box((-w / 2 + 0.05, -d / 2 + 0.03, 0), (w / 2 - 0.05, -d / 2 + 0.1, 0.03), p['color'])
        s.box((-w / 2, -d / 2, h - 0.04), (w / 2, d / 2, h), p['color'])
        for x in (-w / 2 + 0.02, w / 2 - 0.07):
            s.cylinder((x, d / 2 - 0.1, 0.1), 0, 0.1, 0.05, palette.PLASTIC[0])
        s.cylinder((-w / 2 + 0.02, d / 2 - 0.03, h - 0.08), 0, 0.015, w - 0.04, p['color'])
    else:  # mesh cage on feet
        for x in (-w / 2, w / 2 - 0.1):
            for y in (-d / 2, d / 2 - 0.1):
                s.box((x, y, 0), (x + 0.1, y + 0.1, 0.1), p['color'])
        s.box((-w / 2, -d / 2, 0.1), (w / 2, d / 2, 0.14), p['color'])
        for x in (-w / 2, w / 2 - 0.04):
            for y in (-d / 2, d / 2 - 0.04):
                s.box((x, y, 0.14), (x + 0.04, y + 0.04, h), p['color'])
        wire = 0.006
        for y in (-d / 2, d / 2 - wire):  # front and back: vertical and horizontal wires
            for x in np.arange(-w / 2 + 0.1, w / 2 - 0.05, 0.1):
                s.box((x, y, 0.14), (x + wire, y + wire, h), p['color'])
        for x in (-w / 2, w / 2 - wire):
            for y in np.arange(-d / 2 + 0.1, d / 2 - 0.05, 0.1):
                s.box((x, y, 0.14), (x + wire, y + wire, h), p['color'])
        for z in np.arange(0.24, h - 0.05, 0.1):
            for y in (-d / 2, d / 2 - wire):
                s.box((-w / 2, y, z), (w / 2, y + wire, z + wire), p['color'])
            for x in (-w / 2, w / 2 - wire):
                s.box((x, -d / 2, z), (x + wire, d / 2, z + wire), p['color'])
        for y in (-d / 2, d / 2 - 0.03):  # top rails
            s.box((-w / 2, y, h - 0.03), (w / 2, y + 0.03, h), p['color'])


def _build_pipe(s: ColoredSolids, size: Size, p: dict) -> None:
    length, depth, height = size
    diameter, gap = p['diameter'], p['gap']
    flange, radius = diameter / 2, 0.4 * diameter  # flanges set the run's outer diameter
    pitch = diameter + gap
    if p['mount'] == 'wall':  # stacked pipes in front, brackets back to the wall at +y
        centres = [(-depth / 2 + flange, flange + k * pitch) for k in range(p['pipes'])]
    else:  # side by side at the bottom, hangers up to the ceiling
        centres = [(-depth / 2 + flange + k * pitch, flange) for k in range(p['pipes'])]
    joints = np.linspace(-length / 2, length / 2 - 0.03, max(2, int(length / 2.5) + 1))
    for y, z in centres:
        s.cylinder((-length / 2, y, z), 0, radius, length, p['color'])
        for x in joints:
            s.cylinder((x, y, z), 0, flange, 0.03, p['color'])
    supports = np.linspace(-length / 2 + 0.3, length / 2 - 0.34, max(2, int(length / 1.5) + 1))
    for x in supports:
        if p['mount'] == 'wall':
            s.box((x, -depth / 2 + flange, 0), (x + 0.04, depth / 2, height), p['bracket_color'])
        else:
            s.box((x, -depth / 2, height - 0.04), (x + 0.04, depth / 2, height),
                  p['bracket_color'])
            for y, z in centres:
                s.cylinder((x + 0.02, y, z),
                           2,
                           0.008,
                           height - 0.04 - z,
                           p['bracket_color'],
                           segments=8)


_BUILDERS: dict[str, Callable[[ColoredSolids, Size, dict], None]] = {
    'box': _build_primitive,
    'cylinder': _build_primitive,
    'shelf': _build_shelf,
    'cabinet': _build_cabinet,
    'machine': _build_machine,
    'pallet': _build_pallet,
    'crate': _build_crate,
    'cart': _build_cart,
    'bin': _build_bin,
    'pipe': _build_pipe
}


def clutter_mesh(spec: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertices (V, 3), triangles (T, 3) and colors (T, 3) uint8 of a clutter spec, in its
    local frame; closed solids whose bounds are exactly ``spec.size``."""
    solids = ColoredSolids()
    _BUILDERS[spec.params['kind']](solids, tuple(spec.size), spec.params)
    return solids.arrays()
