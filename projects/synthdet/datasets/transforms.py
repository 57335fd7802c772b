"""Training augmentations that make TR3D robust to real scans.

Registered in mmdet3d's ``TRANSFORMS`` when ``projects.synthdet.datasets.synthdet_s3dis`` is
imported (the configs' ``custom_imports``). They work on mmdet3d's ``results`` dicts after
``LoadPointsFromFile`` (``DepthPoints`` with the color in dims 3:6, still 0-255) and
``LoadAnnotations3D`` (axis-aligned ``DepthInstance3DBoxes``); ``with_robustness`` of
``projects/synthdet/config_helpers.py`` puts them right after ``PointSample`` and before
``NormalizePointsColor`` (docs/training.md says why). Like mmdet3d's own transforms they draw
from numpy's global generator, which mmengine seeds (``randomness.seed``, one seed per loader
worker), so a seeded run repeats its augmentations.

Color dropout and xyz jitter are mmdet3d's ``RandomDropPointsColor`` and
``RandomJitterPoints``; ``robust_augmentations`` in ``configs/tr3d/_base_/s3dis-synthdet.py``
lists them with these.
"""
import numpy as np
from mmcv.transforms import BaseTransform
from mmdet3d.registry import TRANSFORMS

from synthdet.voxels import one_point_per_cube

# one counter-clockwise quarter turn of (x, y) row vectors: (x, y) -> (-y, x)
QUARTER_TURN_T = np.array([[0, 1], [-1, 0]])


def _check_probability(name: str, value: float) -> None:
    if not 0.0 <= value <= 1.0:
        raise ValueError(f'{name} must be in [0, 1], got {value}')


def _check_at_least(name: str, value: float, low: float) -> None:
    if value < low:
        raise ValueError(f'{name} must be >= {low}, got {value}')


def _keep_smallest(results: dict, keys: np.ndarray, count: int) -> dict:
    """Keep the ``count`` points with the smallest ``keys`` in their original order, with their
    rows of ``pts_instance_mask`` and ``pts_semantic_mask`` when present."""
    if count >= len(keys):
        return results
    return _keep_rows(results, np.sort(np.argpartition(keys, count - 1)[:count]))


def _keep_rows(results: dict, rows: np.ndarray) -> dict:
    """Keep the points at ``rows`` (ascending) with the same rows of ``pts_instance_mask`` and
    ``pts_semantic_mask`` when present."""
    results['points'] = results['points'][rows]
    for mask in ('pts_instance_mask', 'pts_semantic_mask'):
        if results.get(mask) is not None:
            results[mask] = results[mask][rows]
    return results


@TRANSFORMS.register_module()
class RandomQuarterTurn(BaseTransform):
    """Turn the scene about the z axis by 90, 180 or 270 degrees, exactly.

    Axis-aligned boxes stay axis-aligned and exact: centres turn with the points and the x and
    y sizes swap on odd turns (no enlargement, no rounding: the turn only swaps and negates
    coordinates). Boxes with yaw keep their sizes and turn their yaw instead. Scans reach the
    detector aligned with their walls only up to a quarter turn (``synthdet.prepare`` aligns
    the yaw into [-45, 45) degrees), so every quarter turn is a view the model must handle.

    Args:
        prob: probability of turning; a turn is then 1, 2 or 3 quarters, equally likely
            (``prob=0.75`` makes all four orientations equally likely).
    """

    def __init__(self, prob: float = 0.75) -> None:
        _check_probability('prob', prob)
        self.prob = prob

    def transform(self, results: dict) -> dict:
        """Turn ``points`` and ``gt_bboxes_3d`` (if present) by a random number of quarters."""
        if np.random.rand() >= self.prob:
            return results
        return self.turn(results, int(np.random.randint(1, 4)))

    @staticmethod
    def turn(results: dict, quarter_turns: int) -> dict:
        """Turn ``points`` and ``gt_bboxes_3d`` counter-clockwise by ``quarter_turns`` x 90
        degrees (mmdet3d's positive rotation about z)."""
        quarters = quarter_turns % 4
        rotation_t = np.linalg.matrix_power(QUARTER_TURN_T, quarters)
        points = results['points']
        points.tensor[:, :2] = points.tensor[:, :2] @ points.tensor.new_tensor(rotation_t)
        boxes = results.get('gt_bboxes_3d')
        if boxes is not None:
            boxes.tensor[:, :2] = boxes.tensor[:, :2] @ boxes.tensor.new_tensor(rotation_t)
            if boxes.with_yaw:
                boxes.tensor[:, 6] += quarters * np.pi / 2
            elif quarters % 2:
                boxes.tensor[:, [3, 4]] = boxes.tensor[:, [4, 3]]
        return results

    def __repr__(self) -> str:
        return f'{type(self).__name__}(prob={self.prob})'


@TRANSFORMS.register_module()
class RandomColorJitter(BaseTransform):
    """Change the colors of the whole scene as another scanner or lighting would: contrast
    about the mean grey level, a gain per channel, a brightness offset, then clipped to 0..255.

    Works on colors in 0..255, before ``NormalizePointsColor``. A scene without color (all
    zeros, as color-less scanners and the generator write them) stays without color.

    Args:
        prob: probability of jittering a scene.
        brightness: the offset added to every channel is uniform in
            [-brightness, brightness] (color units, 0..255).
        contrast: the distances to the mean grey level are scaled by a factor uniform in
            [1 - contrast, 1 + contrast].
        channel_gain: each channel is multiplied by its own factor uniform in
            [1 - channel_gain, 1 + channel_gain].
    """

    def __init__(self,
                 prob: float = 0.8,
                 brightness: float = 20.0,
                 contrast: float = 0.2,
                 channel_gain: float = 0.1) -> None:
        _check_probability('prob', prob)
        strengths = dict(brightness=brightness, contrast=contrast, channel_gain=channel_gain)
        for name, value in strengths.items():
            _check_at_least(name, value, 0)
        self.prob = prob
        self.brightness = brightness
        self.contrast = contrast
        self.channel_gain = channel_gain

    def transform(self, results: dict) -> dict:
        """Jitter the color of ``points``."""
        if np.random.rand() >= self.prob:
            return results
        points = results['points']
        colors = points.color
        if not colors.any():
            return results
        contrast = np.random.uniform(1 - self.contrast, 1 + self.contrast)
        gains = np.random.uniform(1 - self.channel_gain, 1 + self.channel_gain, 3)
        offset = np.random.uniform(-self.brightness, self.brightness)
        grey = colors.mean()
        jittered = ((colors - grey) * contrast + grey) * colors.new_tensor(gains) + offset
        points.color = jittered.clamp(0.0, 255.0)
        return results

    def __repr__(self) -> str:
        return (f'{type(self).__name__}(prob={self.prob}, brightness={self.brightness}, '
                f'contrast={self.contrast}, channel_gain={self.channel_gain})')


@TRANSFORMS.register_module()
class RandomPointDropout(BaseTransform):
    """Drop a random share of the scene's points, uniformly, keeping at least ``min_points``.

    Args:
        prob: probability of dropping points from a scene.
        ratio_range: the share of points dropped is uniform in this range (0 <= lo <= hi < 1).
        min_points: never keep fewer points than this (nor drop any from a scene that has at
            most this many).
    """

    def __init__(self,
                 prob: float = 0.3,
                 ratio_range: tuple[float, float] = (0.1, 0.5),
                 min_points: int = 2000) -> None:
        _check_probability('prob', prob)
        low, high = ratio_range
        if not 0.0 <= low <= high < 1.0:
            raise ValueError(f'ratio_range must satisfy 0 <= lo <= hi < 1, got {ratio_range}')
        _check_at_least('min_points', min_points, 1)
        self.prob = prob
        self.ratio_range = (low, high)
        self.min_points = min_points

    def transform(self, results: dict) -> dict:
        """Drop points of ``points`` and the same rows of the point masks."""
        if np.random.rand() >= self.prob:
            return results
        total = len(results['points'])
        ratio = np.random.uniform(*self.ratio_range)
        count = max(round(total * (1.0 - ratio)), min(total, self.min_points))
        return _keep_smallest(results, np.random.rand(total), count)

    def __repr__(self) -> str:
        return (f'{type(self).__name__}(prob={self.prob}, ratio_range={self.ratio_range}, '
                f'min_points={self.min_points})')


@TRANSFORMS.register_module()
class RandomDensityFalloff(BaseTransform):
    """Thin the scene as a handheld or tablet scanner sees it: dense near a virtual sensor,
    sparser with distance.

    The sensor stands at a random (x, y) inside the points' bounding box, ``sensor_height``
    above their lowest point. A point at distance ``d`` from it is kept with probability
    ``clip((full_density_range / d) ** power, min_keep, 1)`` (``power=2``: the density of a
    fixed angular step); at least ``min_points`` points stay. The sensor position is recorded
    as ``results['density_sensor_xyz']``.

    Args:
        prob: probability of thinning a scene.
        full_density_range: points nearer than this (m) are all kept.
        power: how fast the kept share falls with distance beyond it.
        min_keep: the kept share never falls below this, however far.
        sensor_height: range (m) of the sensor's height above the lowest point.
        min_points: never keep fewer points than this.
    """

    def __init__(self,
                 prob: float = 0.3,
                 full_density_range: float = 2.0,
                 power: float = 2.0,
                 min_keep: float = 0.1,
                 sensor_height: tuple[float, float] = (1.0, 1.8),
                 min_points: int = 2000) -> None:
        _check_probability('prob', prob)
        _check_probability('min_keep', min_keep)
        if full_density_range <= 0 or power <= 0:
            raise ValueError(f'full_density_range and power must be > 0, got '
                             f'{full_density_range} and {power}')
        if not 0 <= sensor_height[0] <= sensor_height[1]:
            raise ValueError(f'sensor_height must be a range (lo, hi) with 0 <= lo <= hi, got '
                             f'{sensor_height}')
        _check_at_least('min_points', min_points, 1)
        self.prob = prob
        self.full_density_range = full_density_range
        self.power = power
        self.min_keep = min_keep
        self.sensor_height = tuple(sensor_height)
        self.min_points = min_points

    def keep_probability(self, xyz: np.ndarray, sensor: np.ndarray) -> np.ndarray:
        """The probability of keeping each point of ``xyz`` (N, 3) seen from ``sensor`` (3,)."""
        distance = np.linalg.norm(xyz - sensor, axis=1)
        with np.errstate(divide='ignore'):
            share = (self.full_density_range / distance)**self.power
        return np.clip(share, self.min_keep, 1.0)

    def transform(self, results: dict) -> dict:
        """Thin ``points`` (and the same rows of the point masks) around a random sensor."""
        if np.random.rand() >= self.prob:
            return results
        xyz = results['points'].coord.numpy()
        if len(xyz) == 0:
            return results
        low, high = xyz.min(axis=0), xyz.max(axis=0)
        sensor = np.r_[np.random.uniform(low[:2], high[:2]),
                       low[2] + np.random.uniform(*self.sensor_height)]
        results['density_sensor_xyz'] = sensor
        # a point is kept when u < p; ranking by u / p keeps the same points and tops them up
        # to min_points with the points that came closest to being kept
        ratio = np.random.rand(len(xyz)) / self.keep_probability(xyz, sensor)
        count = max(int((ratio < 1.0).sum()), min(len(xyz), self.min_points))
        return _keep_smallest(results, ratio, count)

    def __repr__(self) -> str:
        return (f'{type(self).__name__}(prob={self.prob}, '
                f'full_density_range={self.full_density_range}, power={self.power}, '
                f'min_keep={self.min_keep}, sensor_height={self.sensor_height}, '
                f'min_points={self.min_points})')


@TRANSFORMS.register_module()
class VoxelGridSample(BaseTransform):
    """Keep one point, drawn at random, of every occupied ``voxel_size`` cube, so that the
    points ``PointSample`` draws next spread over the scanned surfaces instead of piling up
    where the sensor came close.

    A scanner's density falls with the square of the range: a laser scanner puts a hundred
    returns in a 2 cm cube of the floor next to its tripod and a few on an object across the
    room, and the detector merges every return of one of its voxels into one. Sampling a fixed
    number of points at random spends that budget on the near surfaces; sampling from one point
    per cube spends it evenly. Label-free, so the same rule runs in training and testing, on
    generated and real scans.

    Args:
        voxel_size: side (m) of the cubes; the detector's voxel size is the natural choice.
    """

    def __init__(self, voxel_size: float = 0.02) -> None:
        if voxel_size <= 0:
            raise ValueError(f'voxel_size must be > 0, got {voxel_size}')
        self.voxel_size = voxel_size

    def transform(self, results: dict) -> dict:
        """Keep one random point per cube of ``points`` (and the same rows of the point
        masks), in the points' original order."""
        xyz = results['points'].coord.numpy()
        if len(xyz) == 0:
            return results
        return _keep_rows(results, one_point_per_cube(xyz, self.voxel_size, np.random))

    def __repr__(self) -> str:
        return f'{type(self).__name__}(voxel_size={self.voxel_size})'


@TRANSFORMS.register_module()
class ThinRoomStructure(BaseTransform):
    """Keep only a share of the points on the floor, the ceiling and the walls, found from the
    geometry alone (no labels), so that the points ``PointSample`` draws next fall more often
    on objects.

    A terrestrial scanner puts about 90 % of a room's points on its structure (the generator's
    TLS rooms: ceiling 38 %, walls 36 %, floor 17 %, detection classes 2 %), so sampling a fixed
    number of points leaves its far objects a few dozen points. The same rule runs in training
    and testing, on generated and real scans:

    - the floor is the lowest ``bin``-high z slice within ``search`` m above the lowest point
      that holds at least ``min_level_share`` of the points (the ceiling: the highest such
      slice below the highest point), moved to the fullest slice within ``band`` of it (a
      sofa seat or a table top is never the lowest plane); its points are those within
      ``band`` m of it;
    - the walls are the ``cell`` x ``cell`` m columns whose remaining points fill at least
      ``wall_span`` of the floor-to-ceiling height in ``cell``-high slices (no object of a
      room is that tall; a few ceiling points above an object do not fill its column);
      without a ceiling plane (a tablet scan that missed it) the height runs to the highest
      point, without a floor from the lowest;
    - of those structure points a random share ``keep`` stays; every other point stays.

    Args:
        keep: share of the structure points kept.
        band: half-thickness (m) of the floor and ceiling slabs.
        bin: height (m) of the z slices searched for the two levels.
        search: how far (m) from the lowest and highest points the levels are searched.
        min_level_share: least share of the points in a level's slice.
        cell: side (m) of the wall columns.
        wall_span: least z extent of a wall column, as a share of the room height.
        cached_rooms: keep the structure masks of up to this many rooms in memory (packed
            bits), keyed by the room's file and point count, so that a training loader finds
            a room's structure once, not every epoch; only right after ``LoadPointsFromFile``,
            whose points are a room's file unchanged. 0 finds it every time.
    """

    def __init__(self,
                 keep: float = 0.1,
                 band: float = 0.05,
                 bin: float = 0.02,
                 search: float = 0.5,
                 min_level_share: float = 0.01,
                 cell: float = 0.1,
                 wall_span: float = 0.8,
                 cached_rooms: int = 0) -> None:
        _check_probability('keep', keep)
        _check_probability('min_level_share', min_level_share)
        _check_probability('wall_span', wall_span)
        for name, value in dict(band=band, bin=bin, search=search, cell=cell).items():
            if value <= 0:
                raise ValueError(f'{name} must be > 0, got {value}')
        self.keep = keep
        self.band = band
        self.bin = bin
        self.search = search
        self.min_level_share = min_level_share
        self.cell = cell
        self.wall_span = wall_span
        _check_at_least('cached_rooms', cached_rooms, 0)
        self.cached_rooms = cached_rooms
        self._masks: dict[tuple[str, int], np.ndarray] = {}

    def level(self, z: np.ndarray, start: float, stop: float, from_top: bool) -> float | None:
        """The floor (``from_top`` False) or the ceiling: the lowest (highest) ``bin``-high z
        slice in [start, stop) holding at least ``min_level_share`` of the points, moved to the
        most populated slice within ``band`` of it; None if no slice holds that many."""
        edges = np.arange(start, stop + self.bin, self.bin)
        counts, edges = np.histogram(z, edges)
        planes = np.flatnonzero(counts >= self.min_level_share * len(z))
        if len(planes) == 0:
            return None
        first = planes[-1] if from_top else planes[0]
        reach = int(np.ceil(self.band / self.bin))
        near = np.arange(max(first - reach, 0), min(first + reach + 1, len(counts)))
        best = near[np.argmax(counts[near])]
        return float(edges[best] + self.bin / 2)

    def structure(self, xyz: np.ndarray) -> np.ndarray:
        """A boolean mask of the floor, ceiling and wall points of ``xyz`` (N, 3)."""
        z = xyz[:, 2]
        low, high = float(z.min()), float(z.max())
        floor = self.level(z, low, min(low + self.search, high), from_top=False)
        ceiling = self.level(z, max(high - self.search, low), high, from_top=True)
        mask = np.zeros(len(z), dtype=bool)
        for level in (floor, ceiling):
            if level is not None:
                mask |= np.abs(z - level) <= self.band
        height = (high if ceiling is None else ceiling) - (low if floor is None else floor)
        rest = np.flatnonzero(~mask)
        if len(rest) == 0 or height <= 2 * self.band:
            return mask
        cells = np.floor(xyz[rest, :2] / self.cell).astype(np.int64)
        cells -= cells.min(axis=0)
        _, column = np.unique(
            cells[:, 0] * (cells[:, 1].max() + 1) + cells[:, 1], return_inverse=True)
        slices = int(np.ceil(height / self.cell)) + 2
        layer = np.clip(
            np.floor((z[rest] - (high if ceiling is None else ceiling) + height) / self.cell), -1,
            slices - 2).astype(np.int64) + 1
        filled = np.bincount(
            np.unique(column * slices + layer) // slices, minlength=column.max() + 1)
        wall = filled >= self.wall_span * height / self.cell
        mask[rest[wall[column]]] = True
        return mask

    def room_structure(self, results: dict, xyz: np.ndarray) -> np.ndarray:
        """``structure(xyz)``, from the cache when ``cached_rooms`` is set and the room's file
        (``lidar_path``) with as many points was seen before."""
        path = results.get('lidar_path') or results.get('lidar_points', {}).get('lidar_path')
        if not self.cached_rooms or path is None:
            return self.structure(xyz)
        key = (str(path), len(xyz))
        packed = self._masks.get(key)
        if packed is None:
            mask = self.structure(xyz)
            if len(self._masks) < self.cached_rooms:
                self._masks[key] = np.packbits(mask)
            return mask
        return np.unpackbits(packed, count=len(xyz)).astype(bool)

    def transform(self, results: dict) -> dict:
        """Thin the structure points of ``points`` (and the same rows of the point masks)."""
        xyz = results['points'].coord.numpy()
        if len(xyz) == 0:
            return results
        dropped = self.room_structure(results, xyz) & (np.random.rand(len(xyz)) >= self.keep)
        return _keep_rows(results, np.flatnonzero(~dropped))

    def __repr__(self) -> str:
        return (f'{type(self).__name__}(keep={self.keep}, band={self.band}, bin={self.bin}, '
                f'search={self.search}, min_level_share={self.min_level_share}, '
                f'cell={self.cell}, wall_span={self.wall_span}, '
                f'cached_rooms={self.cached_rooms})')
