"""Where each detection goes in the room: one object per thing, on what it stands, which way
it faces, inside the walls (standard library only; metres and radians like the input files).

- Detections of different classes whose boxes overlap with IoU >= ``MERGE_IOU`` are one thing:
  the highest score wins and the others become its alternatives.
- A detection whose footprint centre lies on a table and whose bottom is above the table's
  mid-height stands on that table's top; everything else stands on the floor (``floor_z``).
- A detection with a yaw keeps it. An axis-aligned one (yaw 0, as TR3D predicts on S3DIS) is
  turned by a multiple of 90 degrees by rules users expect: a chair faces the nearest table
  from the side it is at (and is pulled out until its backrest clears the table top), a
  table or sofa puts its back to the nearest wall, a YuMi on a table faces the table's free
  side (away from the wall nearest to the table).
  Every model's front is its local -y side and its back +y.
- A footprint crossing a wall is moved inside, with a warning.
"""
import math

GRID_CELLS = 4  # the spatial index's cell: a quarter of the median footprint side ...
MIN_CELL = 0.05  # ... but no smaller than 5 cm
MAX_KEY_CELLS = 64  # a larger footprint is compared with everything instead of indexed
MERGE_IOU = 0.5
AXIS_ALIGNED = 1e-6  # radians: a smaller |yaw| counts as an axis-aligned detection
ORIENTED_CLASSES = ('chair', 'table', 'sofa', 'yumi')
MAX_PUSHES = 50
PUSH_MARGIN = 1e-4  # metres beyond the wall face a pushed footprint ends
WALL_TOLERANCE = 1e-3  # metres a footprint may reach into a wall before it is moved
TABLE_TOP_SHARE = 0.06  # of a table's height: its top (library.build_table's default)
CHAIR_BACK_SHARE = 0.1  # of a chair's depth: its backrest (library.build_chair's default)


class Placed:
    """One object to build: its detection, label, support, pose and alternatives."""

    def __init__(self, detection: dict, label: str):
        self.detection = detection
        self.label = label
        self.x, self.y = detection['center'][0], detection['center'][1]
        self.length, self.width, self.height = detection['size']
        self.yaw = detection['yaw']
        self.base_z = detection['center'][2] - self.height / 2.0
        self.support: 'Placed | None' = None
        self.orientation = 'detection yaw'
        self.alternatives: list['Placed'] = []

    @property
    def class_name(self) -> str:
        return self.detection['class']

    def footprint(self) -> list[tuple[float, float]]:
        """The footprint's four corners (x, y) in the world."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        half_l, half_w = self.length / 2.0, self.width / 2.0
        return [(self.x + c * u - s * v, self.y + s * u + c * v)
                for u, v in ((-half_l, -half_w), (half_l, -half_w), (half_l, half_w), (-half_l,
                                                                                       half_w))]

    def contains_xy(self, x: float, y: float, margin: float = 0.0) -> bool:
        """Whether (x, y) lies inside the footprint shrunk by ``margin``."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        u = c * (x - self.x) + s * (y - self.y)
        v = -s * (x - self.x) + c * (y - self.y)
        return abs(u) < self.length / 2.0 - margin and abs(v) < self.width / 2.0 - margin


def world_bounds(detection: dict) -> tuple[list[float], list[float]]:
    """Axis-aligned world bounds (low, high) of a detection's yawed box."""
    (x, y, z), (length, width, height) = detection['center'], detection['size']
    c, s = abs(math.cos(detection['yaw'])), abs(math.sin(detection['yaw']))
    half = ((c * length + s * width) / 2.0, (s * length + c * width) / 2.0, height / 2.0)
    return [x - half[0], y - half[1], z - half[2]], [x + half[0], y + half[1], z + half[2]]


def box_iou(first: dict, second: dict) -> float:
    """3D IoU of the two detections' axis-aligned world bounds."""
    (low_a, high_a), (low_b, high_b) = world_bounds(first), world_bounds(second)
    overlap = 1.0
    for axis in range(3):
        overlap *= max(0.0, min(high_a[axis], high_b[axis]) - max(low_a[axis], low_b[axis]))
    volume_a = math.prod(h - lo for lo, h in zip(low_a, high_a))
    volume_b = math.prod(h - lo for lo, h in zip(low_b, high_b))
    return overlap / (volume_a + volume_b - overlap) if overlap > 0.0 else 0.0


class Grid:
    """Keys indexed by the square cells their xy bounds cover: what may overlap a rectangle,
    or lie near a point, is found among a few keys instead of all of them.

    A key covering more than ``MAX_KEY_CELLS`` cells is kept apart and always returned, and a
    query covering more cells than are occupied goes through the occupied ones: memory and
    time stay bounded for any sizes and distances.
    """

    def __init__(self, cell: float):
        self.cell = cell
        self.cells: dict[tuple[int, int], list] = {}
        self.large: list = []  # keys covering too many cells to index

    def _range(self, low: float, high: float) -> range:
        return range(math.floor(low / self.cell), math.floor(high / self.cell) + 1)

    def add(self, key, low_x: float, low_y: float, high_x: float, high_y: float) -> None:
        """Index ``key`` under every cell the bounds cover."""
        columns, rows = self._range(low_x, high_x), self._range(low_y, high_y)
        if len(columns) * len(rows) > MAX_KEY_CELLS:
            self.large.append(key)
            return
        for column in columns:
            for row in rows:
                self.cells.setdefault((column, row), []).append(key)

    def overlapping(self, low_x: float, low_y: float, high_x: float, high_y: float) -> set:
        """Every key whose bounds may overlap these (a superset: same cells)."""
        columns, rows = self._range(low_x, high_x), self._range(low_y, high_y)
        found = set(self.large)
        if len(columns) * len(rows) > len(self.cells):
            for (column, row), keys in self.cells.items():
                if column in columns and row in rows:
                    found.update(keys)
            return found
        for column in columns:
            for row in rows:
                found.update(self.cells.get((column, row), ()))
        return found

    def nearest(self, x: float, y: float, distance) -> list:
        """The keys at the smallest ``distance(key)`` from (x, y), a distance to a point inside
        the key's bounds. Rings of cells are searched outwards until no farther cell can hold
        a nearer key; once a ring has more cells than are occupied, all keys are compared."""
        column, row = math.floor(x / self.cell), math.floor(y / self.cell)
        best, nearest, seen = math.inf, [], set()

        def compare(keys) -> None:
            nonlocal best, nearest
            for key in keys:
                if key in seen:
                    continue
                seen.add(key)
                value = distance(key)
                if value < best:
                    best, nearest = value, [key]
                elif value == best:
                    nearest.append(key)

        compare(self.large)
        radius = 0
        while True:
            if 8 * radius > len(self.cells):
                for keys in self.cells.values():
                    compare(keys)
                return nearest
            for dx in range(-radius, radius + 1):
                for dy in (range(-radius, radius + 1) if abs(dx) == radius else (-radius, radius)):
                    compare(self.cells.get((column + dx, row + dy), ()))
            if best <= radius * self.cell:  # every key nearer lies within this ring
                return nearest
            radius += 1


def grid_for(boxes: list[tuple[float, float, float, float]]) -> Grid:
    """An empty grid whose cell suits xy bounds (low x, low y, high x, high y) like these."""
    sides = sorted(max(high_x - low_x, high_y - low_y) for low_x, low_y, high_x, high_y in boxes)
    median = sides[len(sides) // 2] if sides else 1.0
    return Grid(max(median / GRID_CELLS, MIN_CELL))


def merge_overlapping(detections: list[dict]) -> list[tuple[dict, list[dict]]]:
    """Group cross-class detections overlapping with IoU >= ``MERGE_IOU``.

    Returns (winner, alternatives) pairs in the input order of the winners; the alternatives
    are in decreasing score. A detection joins the first winner (in decreasing score) it
    overlaps enough; only winners sharing a grid cell with it are compared.
    """
    order = sorted(range(len(detections)), key=lambda index: -detections[index]['score'])
    bounds = [world_bounds(detection) for detection in detections]
    xy_bounds = [(low[0], low[1], high[0], high[1]) for low, high in bounds]
    grid = grid_for(xy_bounds)
    winners: dict[int, list[dict]] = {}
    rank: dict[int, int] = {}
    for index in order:
        candidate = detections[index]
        for winner in sorted(grid.overlapping(*xy_bounds[index]), key=rank.__getitem__):
            if detections[winner]['class'] != candidate['class'] and \
                    box_iou(detections[winner], candidate) >= MERGE_IOU:
                winners[winner].append(candidate)
                break
        else:
            winners[index] = []
            rank[index] = len(rank)
            grid.add(index, *xy_bounds[index])
    return [(detections[index], winners[index]) for index in sorted(winners)]


def point_in_polygon(x: float, y: float, polygon: list[list[float]]) -> bool:
    """Whether the point (x, y) lies inside ``polygon`` (even-odd rule)."""
    inside = False
    for index, (x0, y0) in enumerate(polygon):
        x1, y1 = polygon[(index + 1) % len(polygon)]
        if (y0 > y) != (y1 > y) and x < x0 + (y - y0) * (x1 - x0) / (y1 - y0):
            inside = not inside
    return inside


def _nearest_on_boundary(x: float, y: float, polygon: list[list[float]]) -> tuple[float, float]:
    best, best_distance = (x, y), math.inf
    for index, (x0, y0) in enumerate(polygon):
        x1, y1 = polygon[(index + 1) % len(polygon)]
        dx, dy = x1 - x0, y1 - y0
        t = max(0.0, min(1.0, ((x - x0) * dx + (y - y0) * dy) / (dx * dx + dy * dy)))
        px, py = x0 + t * dx, y0 + t * dy
        distance = math.hypot(px - x, py - y)
        if distance < best_distance:
            best, best_distance = (px, py), distance
    return best


def _wall_push(item: Placed, polygon: list[list[float]]) -> tuple[float, float]:
    """The largest move needed to get one footprint corner (or wall corner) out of a wall."""
    best = (0.0, 0.0)
    for x, y in item.footprint():
        if not point_in_polygon(x, y, polygon):
            px, py = _nearest_on_boundary(x, y, polygon)
            dx, dy = px - x, py - y
            length = math.hypot(dx, dy)
            if length > max(WALL_TOLERANCE, math.hypot(*best)):
                scale = (length + PUSH_MARGIN) / length
                best = (dx * scale, dy * scale)
    c, s = math.cos(item.yaw), math.sin(item.yaw)
    for x, y in polygon:  # a room corner poking into the footprint (an L room's inner corner)
        if not item.contains_xy(x, y, WALL_TOLERANCE):
            continue
        u = c * (x - item.x) + s * (y - item.y)
        v = -s * (x - item.x) + c * (y - item.y)
        moves = [(u + item.length / 2.0, (c, s)), (item.length / 2.0 - u, (-c, -s)),
                 (v + item.width / 2.0, (-s, c)), (item.width / 2.0 - v, (s, -c))]
        distance, (dx, dy) = min(moves)
        if distance > math.hypot(*best):
            best = (dx * (distance + PUSH_MARGIN), dy * (distance + PUSH_MARGIN))
    return best


def keep_inside(item: Placed, polygon: list[list[float]]) -> float | None:
    """Move ``item`` until its footprint is inside ``polygon``; returns the distance moved,
    or None when it cannot be fitted (left where it was)."""
    start = (item.x, item.y)
    for _ in range(MAX_PUSHES):
        dx, dy = _wall_push(item, polygon)
        if dx == 0.0 and dy == 0.0:
            return math.hypot(item.x - start[0], item.y - start[1])
        item.x += dx
        item.y += dy
    item.x, item.y = start
    return None


def _turn(item: Placed, quarter_turns: int, rule: str) -> None:
    """Turn an axis-aligned item by ``quarter_turns`` x 90 degrees, keeping its world box."""
    if quarter_turns % 2:
        item.length, item.width = item.width, item.length
    item.yaw = quarter_turns * math.pi / 2.0
    item.orientation = rule


def _front(quarter_turns: int) -> tuple[float, float]:
    """World direction of the local -y (front) side after ``quarter_turns`` x 90 degrees."""
    angle = quarter_turns * math.pi / 2.0
    return math.sin(angle), -math.cos(angle)


def _facing(dx: float, dy: float) -> int:
    """The quarter turn whose front points most along (dx, dy)."""
    return max(range(4), key=lambda turns: _front(turns)[0] * dx + _front(turns)[1] * dy)


def _table_side(item: Placed, table: Placed) -> tuple[float, tuple[float, float]]:
    """Distance from ``item``'s centre to the table's footprint, and the world outward normal
    of the table side it is at (the nearest side when it is under the table)."""
    c, s = math.cos(table.yaw), math.sin(table.yaw)
    u = c * (item.x - table.x) + s * (item.y - table.y)
    v = -s * (item.x - table.x) + c * (item.y - table.y)
    half_u, half_v = table.length / 2.0, table.width / 2.0
    distance = math.hypot(max(abs(u) - half_u, 0.0), max(abs(v) - half_v, 0.0))
    _, (normal_u, normal_v) = max([(u - half_u, (1.0, 0.0)), (-u - half_u, (-1.0, 0.0)),
                                   (v - half_v, (0.0, 1.0)), (-v - half_v, (0.0, -1.0))])
    return distance, (c * normal_u - s * normal_v, s * normal_u + c * normal_v)


def _bounds_2d(points: list[tuple[float, float]]) -> tuple[float, float, float, float]:
    xs, ys = [x for x, _ in points], [y for _, y in points]
    return min(xs), min(ys), max(xs), max(ys)


def _quarter_turned(yaw: float) -> bool:
    return abs(math.remainder(yaw, math.pi / 2.0)) < AXIS_ALIGNED


class Tables:
    """The tables of a room, in order, with a grid of their footprints' bounds."""

    def __init__(self, tables: list[Placed]):
        self.items = tables
        bounds = [_bounds_2d(table.footprint()) for table in tables]
        self.grid = grid_for(bounds)
        for index, box in enumerate(bounds):
            self.grid.add(index, *box)

    def overlapping(self,
                    low_x: float,
                    low_y: float,
                    high_x: float,
                    high_y: float,
                    after: int = -1) -> list[int]:
        """Indices (ascending, above ``after``) of the tables whose bounds may overlap these."""
        return sorted(
            index for index in self.grid.overlapping(low_x, low_y, high_x, high_y)
            if index > after)


def clear_backrest(item: Placed, tables: Tables) -> list[tuple[Placed, float]]:
    """Pull a chair back until its backrest is off the tops of the tables it is pushed under
    (a backrest taller than the table would pierce the top); returns (table, distance) pairs.

    Only for a chair and tables turned by multiples of 90 degrees (their footprints are then
    world-aligned rectangles).
    """
    if item.class_name != 'chair' or not _quarter_turned(item.yaw):
        return []
    back_x, back_y = -math.sin(item.yaw), math.cos(item.yaw)  # local +y in the world
    pulls = []
    index = -1  # the tables in order; the strip moves with each pull
    while True:
        c, s = math.cos(item.yaw), math.sin(item.yaw)
        strip = [(item.x + c * u - s * v, item.y + s * u + c * v)
                 for u in (-item.length / 2.0, item.length / 2.0)
                 for v in ((0.5 - CHAIR_BACK_SHARE) * item.width, item.width / 2.0)]
        pull = _first_pull(item, strip, tables, index)
        if pull is None:
            return pulls
        index, distance = pull
        item.x += back_x * distance
        item.y += back_y * distance
        pulls.append((tables.items[index], distance))


def _first_pull(item: Placed, strip: list[tuple[float, float]], tables: Tables,
                after: int) -> tuple[int, float] | None:
    """The first table after ``after`` whose top the backrest ``strip`` lies under, and how
    far the chair has to move back to clear it."""
    back_x, back_y = -math.sin(item.yaw), math.cos(item.yaw)
    low_x, low_y, high_x, high_y = _bounds_2d(strip)
    for index in tables.overlapping(low_x, low_y, high_x, high_y, after):
        table = tables.items[index]
        if not _quarter_turned(table.yaw) or \
                item.height <= (1.0 - TABLE_TOP_SHARE) * table.height:
            continue
        table_low_x, table_low_y, table_high_x, table_high_y = _bounds_2d(table.footprint())
        if min(high_x, table_high_x) - max(low_x, table_low_x) <= WALL_TOLERANCE or \
                min(high_y, table_high_y) - max(low_y, table_low_y) <= WALL_TOLERANCE:
            continue
        strip_near = min(x * back_x + y * back_y for x, y in strip)
        table_far = max(x * back_x + y * back_y for x, y in table.footprint())
        return index, table_far - strip_near + PUSH_MARGIN
    return None


def orient(item: Placed, tables: Tables, polygon: list[list[float]] | None) -> None:
    """Choose the front of an axis-aligned detection by the class's rule (see module doc)."""
    if abs(math.remainder(item.yaw, 2.0 * math.pi)) > AXIS_ALIGNED or \
            item.class_name not in ORIENTED_CLASSES:
        return
    if item.class_name == 'chair' and tables.items:
        nearest = tables.grid.nearest(item.x, item.y,
                                      lambda index: _table_side(item, tables.items[index])[0])
        table = tables.items[min(nearest)]  # the first of the nearest, in order
        normal_x, normal_y = _table_side(item, table)[1]
        _turn(item, _facing(-normal_x, -normal_y), f'faces {table.label}')
    elif item.class_name in ('table', 'sofa') and polygon:
        wall_x, wall_y = _nearest_on_boundary(item.x, item.y, polygon)
        _turn(item, _facing(item.x - wall_x, item.y - wall_y), 'back to the nearest wall')
    elif item.class_name == 'yumi' and item.support is not None and polygon:
        table = item.support  # its free side is the one away from the table's nearest wall
        wall_x, wall_y = _nearest_on_boundary(table.x, table.y, polygon)
        _turn(item, _facing(table.x - wall_x, table.y - wall_y),
              f'faces the free side of {table.label}')


def find_support(item: Placed, tables: Tables) -> Placed | None:
    """The table ``item`` stands on: its footprint centre on the table and its bottom above the
    table's mid-height (the highest such table), else None (the floor)."""
    if item.class_name == 'table':
        return None
    bottom = item.detection['center'][2] - item.detection['size'][2] / 2.0
    candidates = [
        table for table in map(tables.items.__getitem__,
                               tables.overlapping(item.x, item.y, item.x, item.y))
        if table.contains_xy(item.x, item.y) and bottom >= table.detection['center'][2] - 1e-9
    ]
    return max(candidates, key=lambda table: table.detection['center'][2], default=None)


def arrange(detections: list[dict], corners: dict | None) -> tuple[list[Placed], list[str]]:
    """Place the detections (already filtered by score); returns (objects, warnings).

    Alternatives hang off their winner (``Placed.alternatives``) and are placed by the same
    rules. Without ``corners`` objects keep their box bottoms (no floor is known) and no wall
    or wall-based orientation rule applies.
    """
    warnings = []
    counts: dict[str, int] = {}
    placed = []
    for winner, alternatives in merge_overlapping(detections):
        counts[winner['class']] = counts.get(winner['class'], 0) + 1
        item = Placed(winner, f'{winner["class"]} {counts[winner["class"]]}')
        item.alternatives = [
            Placed(other, f'{other["class"]} (alternative to {item.label})')
            for other in alternatives
        ]
        placed.append(item)
    polygon = corners['corners'] if corners else None
    everything = [entry for item in placed for entry in [item] + item.alternatives]
    tables, indexed = Tables([]), False  # tables need no other table to be placed
    for item in sorted(everything, key=lambda entry: entry.class_name != 'table'):
        if item.class_name != 'table' and not indexed:  # the tables are in place now
            tables, indexed = Tables([item for item in placed if item.class_name == 'table']), True
        item.support = find_support(item, tables)
        orient(item, tables, polygon)
        for table, distance in clear_backrest(item, tables):
            warnings.append(f'{item.label} pulled {distance:.2f} m out from under {table.label}: '
                            'its backrest crossed the table top')
        if polygon is not None:
            if item.support is not None:  # moves with its table first
                item.x += item.support.x - item.support.detection['center'][0]
                item.y += item.support.y - item.support.detection['center'][1]
            moved = keep_inside(item, polygon)
            if moved is None:
                warnings.append(f'{item.label} does not fit inside the walls: left where '
                                'it was detected')
            elif moved > 0.0:
                warnings.append(f'{item.label} crossed a wall by {moved:.2f} m: moved inside')
        if item.support is not None:
            item.base_z = item.support.base_z + item.support.height
        elif corners is not None:
            item.base_z = corners['floor_z']
    return placed, warnings
