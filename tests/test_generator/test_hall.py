"""Factory halls from the real generator, and whole-hall detection by windows on their points.

A module fixture generates one small hall (20 m x 15 m, 1.2M points, partitions) with real bpy
and Embree. The window cutting and merging run on its real points; where the model is not the
subject, a deterministic stand-in detector finds every object of a window from the points'
instance labels (a cut object gives a cut box, as a model would see it). The real model on
windows is tested in tests/test_tools/test_scan2cad.py.
"""
import json
import math
from pathlib import Path

import bpy  # noqa: F401  (bpy before open3d: both ship libtbb)
import numpy as np
import pytest
from mmengine.config import Config

from generator.__main__ import main as generate
from generator.config import DEFAULTS, ConfigError, load_config
from generator.layout import AssetSpec, PlacedObject, boxes_intersect, sample_room
from projects.synthdet.inference.windows import (Detections, WindowSpec, detect_in_windows,
                                                 merge_window_detections, plan_windows,
                                                 window_spec_from_config,
                                                 window_spec_from_training)
from synthdet.classes import GENERATED_CLASSES
from synthdet.geometry import box_corners_xy
from synthdet.point_text import read_point_file

REPO = Path(__file__).resolve().parents[2]
HALL_POINTS = 1_200_000
# the paper sensor (a cross per bay): partition points exactly on their wall
HALL_CONFIG = ('hall:\n  width: [20.0, 20.0]\n  depth: [15.0, 15.0]\n  partitions: 0.6\n'
               'scanner:\n  sensors: {paper: 1.0}\n')
SPEC = window_spec_from_config(Config.fromfile(str(REPO / 'configs/tr3d/exp2_cpu.py')))


@pytest.fixture(scope='module')
def asset_cache(tmp_path_factory):
    return tmp_path_factory.mktemp('assets')


@pytest.fixture(scope='module')
def hall(tmp_path_factory, asset_cache) -> dict:
    """One generated hall: its meta.json, points (N, 6) and per-point instance names."""
    root = tmp_path_factory.mktemp('hall')
    config = root / 'hall.yaml'
    config.write_text(HALL_CONFIG)
    assert generate([
        '--out',
        str(root / 'out'), '--areas', '1', '--rooms-per-area', '1', '--points',
        str(HALL_POINTS), '--seed', '3', '--config',
        str(config), '--asset-cache',
        str(asset_cache), '--quiet'
    ]) == 0
    room = root / 'out' / 'Area_1' / 'factory_1'
    parts, names = [], []
    for path in sorted((room / 'Annotations').glob('*.txt')):
        points, _ = read_point_file(path)
        parts.append(points)
        names += [path.stem] * len(points)
    return {
        'meta': json.loads((room / 'meta.json').read_text()),
        'points': np.concatenate(parts),
        'instances': np.array(names),
        'room': room
    }


def test_hall_config_section_is_validated(tmp_path):
    config = tmp_path / 'hall.yaml'
    config.write_text('hall:\n  bay: [2.0, 3.0]\n')
    with pytest.raises(ConfigError, match='hall.bay'):
        load_config(config)
    config.write_text('hall:\n  aisles: 3\n')
    with pytest.raises(ConfigError, match='unknown key "hall.aisles"'):
        load_config(config)
    assert 'hall' not in load_config()  # rooms' configurations (and meta.json) are unchanged


def test_generated_hall_follows_the_rules(hall):
    meta, points, instances = hall['meta'], hall['points'], hall['instances']
    room = meta['room']
    assert room['shape'] == 'hall' and len(points) == HALL_POINTS
    polygon = np.array(room['polygon'])
    assert np.ptp(polygon, axis=0).tolist() == [20.0, 15.0]
    bays = [np.array(b) for b in room['bays']]
    assert len(bays) > 1
    assert sum(np.prod(np.ptp(b, axis=0)) for b in bays) == pytest.approx(300.0)
    assert all(7.0 <= side <= 10.0 for b in bays for side in np.ptp(b, axis=0))
    assert len(meta['generator']['sensor_path']) == 2 * len(bays)  # a cross per bay
    assert room['partitions'], 'partitions: 0.6 over the inner bay boundaries made none'
    for partition in room['partitions']:  # partition points lie on their wall line
        start, end = np.array(partition['start']), np.array(partition['end'])
        on_wall = points[instances == partition['instance'], :2]
        assert len(on_wall) > 100
        direction = (end - start) / np.linalg.norm(end - start)
        offsets = on_wall - start
        assert np.abs(offsets @ np.array([-direction[1], direction[0]])).max() < 2e-3
        u = offsets @ direction
        assert not np.any((u > partition['passage'][0] + 2e-3)
                          & (u < partition['passage'][1] - 2e-3))
    objects = [o for o in meta['objects'] if o['class'] in GENERATED_CLASSES]
    assert len(objects) >= 10
    for obj in objects:  # each object inside one bay, its points inside its box
        corners = box_corners_xy(
            np.array(obj['box']['center']), obj['box']['size'], obj['box']['yaw'])
        assert any(
            np.all((corners >= bay.min(axis=0) - 1e-6) & (corners <= bay.max(axis=0) + 1e-6))
            for bay in bays), obj['instance']
        own = points[instances == obj['instance']]
        local = (own[:, :2] - obj['box']['center'][:2]) @ np.array([[
            math.cos(obj['box']['yaw']), -math.sin(obj['box']['yaw'])
        ], [math.sin(obj['box']['yaw']), math.cos(obj['box']['yaw'])]])
        assert np.all(np.abs(local) <= np.array(obj['box']['size'][:2]) / 2 + 2e-3)


def test_hall_objects_do_not_intersect(hall):
    placed = [
        PlacedObject(o['instance'], AssetSpec(o['class'], '', '', {}, tuple(o['box']['size'])),
                     np.array(o['box']['center']), o['box']['yaw'])
        for o in hall['meta']['objects']
    ]
    on = {o['instance']: o['on'] for o in hall['meta']['objects']}
    for i, a in enumerate(placed):
        for b in placed[i + 1:]:
            if on[a.instance] != b.instance and on[b.instance] != a.instance:
                assert not boxes_intersect(a, b), (a.instance, b.instance)


def test_window_rule_gives_the_configured_windows(asset_cache):
    """inference_window in the configs is the documented rule on the generator's defaults."""
    from generator.assets import default_library
    rng = np.random.default_rng(0)
    extents = np.array(
        [np.ptp(sample_room(rng, DEFAULTS['room'])[1], axis=0) for _ in range(4000)])
    library = default_library(asset_cache, seed=0)
    sizes = np.array([i.size for c in library.classes() for i in library.instances(c)])
    assert window_spec_from_training(extents, sizes) == SPEC == WindowSpec(8.0, 2.6)


def test_windows_overlap_by_the_largest_object_and_cores_tile_the_plane(hall):
    xy = hall['points'][:, :2]
    windows = plan_windows(xy.min(axis=0), xy.max(axis=0), SPEC)
    assert len(windows) == 4 * 3  # 20 m -> 4 windows of 8 m, 15 m -> 3
    for window in windows:
        assert np.allclose(window.high - window.low, SPEC.size)
        inner_low, inner_high = np.isfinite(window.core_low), np.isfinite(window.core_high)
        assert np.all((window.core_low - window.low)[inner_low] >= SPEC.overlap / 2 - 1e-9)
        assert np.all((window.high - window.core_high)[inner_high] >= SPEC.overlap / 2 - 1e-9)
    sample = xy[::97]
    in_core = np.stack(
        [np.all((sample >= w.core_low) & (sample < w.core_high), axis=1) for w in windows])
    assert np.all(in_core.sum(axis=0) == 1)  # every point is central to exactly one window
    in_window = np.stack([np.all((sample >= w.low) & (sample <= w.high), axis=1) for w in windows])
    assert np.all(in_window[in_core])  # ... and lies inside it


class InstanceDetector:
    """Stand-in detector: one axis-aligned box per instance of a detection class in the window
    (from the points' instance column), scored by the share of the instance's points it holds."""

    def __init__(self, instances: np.ndarray, classes: list[str]):
        self.names, self.column = np.unique(instances, return_inverse=True)
        self.totals = np.bincount(self.column)
        self.classes = classes
        self.calls: list[set[str]] = []

    def points(self, points: np.ndarray) -> np.ndarray:
        return np.hstack([points, self.column[:, None].astype(np.float64)])

    def __call__(self, points: np.ndarray) -> Detections:
        boxes, scores, labels, seen = [], [], [], set()
        ids = points[:, 6].astype(np.int64)
        for index in np.unique(ids):
            name = self.names[index]
            cls = name.rsplit('_', 1)[0]
            own = points[ids == index, :3]
            if cls not in self.classes or len(own) < 20:
                continue
            low, high = own.min(axis=0), own.max(axis=0)
            boxes.append([*(low + high) / 2, *(high - low), 0.0])
            scores.append(len(own) / self.totals[index])
            labels.append(self.classes.index(cls))
            seen.add(name)
        self.calls.append(seen)
        if not boxes:
            return Detections.empty()
        return Detections(np.array(boxes), np.array(scores), np.array(labels))


def _truth_boxes(hall, detector: InstanceDetector) -> dict[str, np.ndarray]:
    """Each detectable instance's axis-aligned box from all of its points."""
    truth = {}
    xyz = hall['points'][:, :3]
    for index, name in enumerate(detector.names):
        own = xyz[detector.column == index]
        if name.rsplit('_', 1)[0] in detector.classes and len(own) >= 20:
            low, high = own.min(axis=0), own.max(axis=0)
            truth[name] = np.concatenate([(low + high) / 2, high - low])
    return truth


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    low = np.maximum(a[:3] - a[3:6] / 2, b[:3] - b[3:6] / 2)
    high = np.minimum(a[:3] + a[3:6] / 2, b[:3] + b[3:6] / 2)
    inter = np.prod(np.clip(high - low, 0, None))
    return float(inter / (np.prod(a[3:6]) + np.prod(b[3:6]) - inter))


def test_hall_detected_by_windows_merges_seams_without_duplicates(hall):
    classes = list(GENERATED_CLASSES)
    detector = InstanceDetector(hall['instances'], classes)
    truth = _truth_boxes(hall, detector)
    merged, windows = detect_in_windows(
        detector.points(hall['points']), detector, SPEC, iou_thr=0.5, progress=False)
    assert len(windows) == 12 and len(detector.calls) == 12
    windows_per_object = {name: sum(name in seen for seen in detector.calls) for name in truth}
    assert max(windows_per_object.values()) >= 2  # objects across seams were seen (cut) twice
    assert len(merged.boxes) == len(truth)  # no duplicates ...
    for name, box in truth.items():  # ... and every object once, whole, with its class
        ious = [_iou(box, found) for found in merged.boxes]
        best = int(np.argmax(ious))
        assert ious[best] > 0.999, name
        assert classes[merged.labels[best]] == name.rsplit('_', 1)[0]
    assert np.all(np.diff(merged.scores) <= 0)


def test_merging_drops_what_the_core_rule_and_nms_remove(hall):
    """Without the core rule the windows' raw detections hold duplicates; NMS alone removes
    those that overlap the kept box enough."""
    detector = InstanceDetector(hall['instances'], list(GENERATED_CLASSES))
    points = detector.points(hall['points'])
    windows = plan_windows(points[:, :2].min(axis=0), points[:, :2].max(axis=0), SPEC)
    per_window = []
    for w in windows:
        inside = np.all((points[:, :2] >= w.low) & (points[:, :2] <= w.high), axis=1)
        per_window.append(detector(points[inside]))
    raw = sum(len(d.boxes) for d in per_window)
    truth = _truth_boxes(hall, detector)
    assert raw > len(truth)
    merged = merge_window_detections(per_window, windows, iou_thr=0.5)
    assert len(merged.boxes) == len(truth)


def test_room_sized_scan_is_one_window_and_the_detector_output(hall):
    """A scan within one window's size is detected once, as a whole, unchanged."""
    detector = InstanceDetector(hall['instances'], list(GENERATED_CLASSES))
    points = detector.points(hall['points'])
    first_bay = np.all(points[:, :2] <= SPEC.size - 0.5, axis=1)
    found, windows = detect_in_windows(points[first_bay], detector, SPEC, 0.5, progress=False)
    assert len(windows) == 1 and len(detector.calls) == 1
    direct = detector(points[first_bay])
    assert np.array_equal(found.boxes, direct.boxes) and np.array_equal(
        found.scores, direct.scores) and np.array_equal(found.labels, direct.labels)
