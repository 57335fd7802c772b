"""Sensor models (generator/sensors.py) on real Open3D/Embree: hand-made box rooms for the TLS grid,
range noise and mixed pixels, the tablet's range window and dropouts, the paper profile's uniform
directions; and small real rooms from ``python -m generator`` for the per-room mix and
determinism."""
import json
from pathlib import Path

import bpy  # noqa: F401  (bpy before open3d: both ship libtbb)
import numpy as np
import pytest

from generator.__main__ import main
from generator.assets.palette import METAL
from generator.config import DEFAULTS, ConfigError, load_config
from generator.scanner import Scanner, TriangleScene
from generator.sensors import (SENSOR_MODELS, RoomGeometry, cast_tablet, cast_tls, choose_sensor,
                               scan_room, scan_tls, tls_grid)
from synthdet.point_text import read_point_file
from tests.test_generator_pipeline import _same_tree, box

REPO = Path(__file__).resolve().parents[1]
TLS = dict(DEFAULTS['scanner']['tls'], mixed_pixels=0.0, range_noise=[0.0, 0.0])
TABLET = DEFAULTS['scanner']['tablet']
BATCH = 65536


def room_scene(size, cubes=()) -> TriangleScene:
    """A box room ``size`` (part 0, structure) with cubes (lo, hi, rgb), each a movable part."""
    vertices, triangles = box((0, 0, 0), size, True)
    vertices, triangles = [vertices], [triangles]
    colors, part = [[200, 200, 200]] * 12, [0] * 12
    for index, (lo, hi, rgb) in enumerate(cubes, start=1):
        v, f = box(lo, hi, False)
        triangles.append(f + 8 * index)
        vertices.append(v)
        colors += [rgb] * 12
        part += [index] * 12
    return TriangleScene(
        np.concatenate(vertices),
        np.concatenate(triangles).astype(np.int32), np.array(colors, np.uint8),
        np.array(part, np.int32), np.array([False] + [True] * len(cubes)))


def objects(scanner: Scanner) -> np.ndarray:
    """Per triangle: does it belong to an object (here the movable cubes)."""
    return scanner.scene.movable[scanner.scene.part]


def true_ranges(scanner: Scanner, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Noise-free ranges along the given rays."""
    t_hit, _ = scanner.cast(scanner.full_scene, np.ascontiguousarray(origins),
                            np.ascontiguousarray(directions))
    return t_hit.astype(np.float64)


def grid_position(points: np.ndarray, station: np.ndarray, step: float) -> np.ndarray:
    """Azimuth and elevation of each point seen from ``station``, in units of ``step`` degrees."""
    rel = points - station
    azimuth = np.degrees(np.arctan2(rel[:, 1], rel[:, 0])) % 360.0
    elevation = np.degrees(np.arctan2(rel[:, 2], np.hypot(rel[:, 0], rel[:, 1])))
    return np.stack([azimuth, elevation], axis=1) / step


def unit(degrees: np.ndarray) -> np.ndarray:
    """Unit vectors (N, 3) float32 of (azimuth, elevation) pairs in degrees."""
    azimuth, elevation = np.radians(degrees).T
    return np.stack([np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth),
                     np.sin(elevation)], axis=1).astype(np.float32)


def test_tls_directions_lie_on_the_angular_grid_of_its_step():
    scanner = Scanner(room_scene((12, 6, 3), [((5, 2, 0), (6, 3, 1), (200, 0, 0))]))
    station = np.array([[2.0, 3.0, 1.5]])
    cfg = dict(TLS, range_noise=[0.005, 0.002], mixed_pixels=0.5)
    scan, step = scan_tls(scanner, station, 50000, np.random.default_rng(0), cfg, BATCH,
                          objects(scanner))
    assert len(scan.xyz) == 50000 and 0.1 < step < 5
    assert np.isclose(360.0 / step, round(360.0 / step))  # a whole number of azimuth steps
    position = grid_position(scan.xyz, station[0], step)
    assert np.abs(position - np.round(position)).max() < 1e-6
    assert position[:, 1].min() >= cfg['min_elevation_deg'] / step - 1e-6
    assert (scan.part == 1).sum() > 100 and len(np.unique(scan.triangle)) > 12
    # a coarser fixed step: every beam of the grid that hits is there, once
    xyz, _, _ = cast_tls(scanner, station, 2.0, np.random.default_rng(0), TLS, BATCH,
                         objects(scanner))
    azimuth, elevation = tls_grid(2.0, TLS['min_elevation_deg'])
    assert len(xyz) == len(azimuth) * len(elevation)  # a closed room returns every beam
    cells = np.round(grid_position(xyz, station[0], 2.0)).astype(int)
    assert len(np.unique(cells, axis=0)) == len(xyz)


def test_tls_range_noise_grows_with_distance():
    scanner = Scanner(room_scene((30, 4, 3)))
    station = np.array([[1.0, 2.0, 1.5]])
    a, b = 0.002, 0.002
    xyz, _, _ = cast_tls(scanner, station, 0.25, np.random.default_rng(1),
                         dict(TLS, range_noise=[a, b]), BATCH, objects(scanner))
    measured = np.linalg.norm(xyz - station, axis=1)
    truth = true_ranges(scanner, np.repeat(station, len(xyz), axis=0),
                        (xyz - station) / measured[:, None])
    error = measured - truth
    stds = []
    for low, high in ((1.0, 3.0), (8.0, 12.0), (20.0, 28.0)):
        rows = (truth > low) & (truth < high)
        assert rows.sum() > 300
        stds.append(error[rows].std())
        # the model: std a + b * d, checked on the normalised error
        assert abs(np.std(error[rows] / (a + b * truth[rows])) - 1.0) < 0.1
    assert stds[0] < stds[1] < stds[2] and stds[2] > 4 * stds[0]


def test_tls_mixed_pixels_appear_only_at_depth_edges():
    cube = ((4, 2.5, 0), (5, 3.5, 1), (0, 0, 200))
    station = np.array([[1.5, 3.0, 1.5]])
    cfg = dict(TLS, mixed_pixels=1.0)
    step = 0.5
    for cubes in ([], [cube]):
        scanner = Scanner(room_scene((10, 6, 3), cubes))
        xyz, _, _ = cast_tls(scanner, station, step, np.random.default_rng(2), cfg, BATCH,
                             objects(scanner))
        measured = np.linalg.norm(xyz - station, axis=1)
        directions = (xyz - station) / measured[:, None]
        off = np.abs(measured - true_ranges(scanner, np.repeat(station, len(xyz), 0),
                                            directions)) > 1e-3
        if not cubes:  # walls, floor (even at grazing angles) and corners: no depth edge
            assert not off.any()
            continue
        assert off.sum() > 20
        # every mixed return: a grid neighbour of its beam hits the other surface (cube vs room)
        # and the return lies between the two surfaces along its beam
        for cell, r in zip(np.round(grid_position(xyz[off], station[0], step)), measured[off]):
            beams = unit(np.array([cell, cell + [1, 0], cell - [1, 0], cell + [0, 1],
                                   cell - [0, 1]]) * step)
            t_hit, prim = scanner.cast(scanner.full_scene, np.repeat(station, 5, 0), beams)
            part = scanner.scene.part[prim]
            other = part[1:] != part[0]
            assert other.any()
            assert min(t_hit[0], t_hit[1:][other].min()) - 1e-4 <= r
            assert r <= max(t_hit[0], t_hit[1:][other].max()) + 1e-4
