"""Room outlines built on the walls a scan shows (configurator/wall_evidence.py), on scans made
here with the faults of real ones: a reconstruction with walls missing, walls that stop low,
one depth view of a room, an L-shaped room seen from one side with occlusions."""
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from configurator.corners import CornerParams, detect_corners, room_outline
from configurator.wall_evidence import WallEvidenceParams, wall_planes, walled_outline
from synthdet.geometry import distance_to_polygon, first_self_crossing, points_in_polygon
from synthdet.scan_io import write_scan
from tests.room_scans import sample_box, sample_flat, sample_walls
from tests.test_configurator.test_real_scan_geometry import (DEPTH, RECTANGLE, WIDTH, depth_view, in_view,
                                          occluded_view, room_scan)

REPO = Path(__file__).resolve().parents[2]
L_ROOM = np.array([[0.0, 0.0], [0.0, 6.0], [4.0, 6.0], [4.0, 3.0], [7.0, 3.0], [7.0, 0.0]])


def corner_errors(found: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Distance from every true corner to the nearest found corner."""
    return np.linalg.norm(truth[:, None] - found[None], axis=2).min(axis=1)


def on_wall(points: np.ndarray, axis: int, offset: float, low: float, high: float) -> np.ndarray:
    """Which points lie on the wall ``axis`` = ``offset`` (2 cm) between ``low`` and ``high``
    along the other axis."""
    return (np.abs(points[:, axis] - offset) < 0.02) & (points[:, 1 - axis] > low) & \
        (points[:, 1 - axis] < high)


def l_room_scan(seed: int = 0) -> np.ndarray:
    """The L-shaped room ``L_ROOM`` (walls 2.6 m, no ceiling, floor at 0) with a table and
    a cabinet, as x y z r g b."""
    rng = np.random.default_rng(seed)
    floor = sample_flat(L_ROOM, 0.0, int(1500 * 33), rng, (150, 140, 130))
    walls = sample_walls(L_ROOM, 2.6, 1500.0, rng, openings=True)
    table = sample_box((np.array([1.5, 4.5]), np.array([1.2, 0.8, 0.75]), 0.0, False), 6000.0,
                       rng)
    cabinet = sample_box((np.array([5.5, 0.35]), np.array([1.0, 0.5, 1.8]), 0.0, True),
                         6000.0, rng)
    return np.concatenate([floor, walls, table, cabinet])


def walls_missing_scan() -> np.ndarray:
    """A 6 m x 5 m reconstruction that kept one wall whole and 1.5 m of another (and the
    lowest 0.8 m of every wall, the floor and the furniture)."""
    points = room_scan(ceiling=False, height=2.5, furniture=3, seed=11)
    high = points[:, 2] > 0.05
    kept = on_wall(points, 1, DEPTH, -1.0, WIDTH + 1) | on_wall(points, 0, 0.0, 3.5, 5.0)
    return points[~high | kept | (points[:, 2] < 0.8)]


def test_reconstruction_with_walls_missing_is_traced_on_the_walls_it_has():
    """A reconstruction that kept one wall whole and 1.5 m of another: wall points back 34 %
    of the footprint's outline (before: no walls found, an approximate floor). The outline
    lies on both walls, closes along the floor's extent elsewhere and is marked partial."""
    outline = detect_corners(walls_missing_scan())
    assert not outline.approximate and len(outline.corners) == 4
    assert corner_errors(outline.corners, RECTANGLE).max() < 0.05, outline.corners
    assert 0.2 < outline.quality['walls_seen'] < 0.75
    assert any(note.startswith('partial outline') for note in outline.notes)


def test_floor_seen_through_a_door_stays_out_of_a_partial_outline():
    """A reconstruction without one wall that also saw 2.5 m of a hall's floor through a door:
    the traced outline (the hall, a bump between two halves of one wall, dropped) is backed
    more (48 %) than the outline built on the wall planes, which takes the hall's floor in
    (41 %). The traced one is kept: the room, its missing side along the floor's extent."""
    rng = np.random.default_rng(11)
    points = room_scan(ceiling=False, height=2.5, furniture=3, seed=11)
    door = on_wall(points, 0, 0.0, 1.5, 2.5) & (points[:, 2] < 2.1)
    missing = on_wall(points, 1, DEPTH, -1.0, WIDTH + 1) & (points[:, 2] > 0.05)
    hall = sample_flat(np.array([[-2.5, 0.5], [-2.5, 3.5], [0.0, 3.5], [0.0, 0.5]]), 0.0,
                       9000, rng, (150, 140, 130))
    outline = detect_corners(np.concatenate([points[~door & ~missing], hall]))
    assert not outline.approximate and len(outline.corners) == 4
    assert corner_errors(outline.corners, RECTANGLE).max() < 0.06, outline.corners
    assert any(note.startswith('partial outline') for note in outline.notes)


def test_walls_that_stop_low_still_bound_the_room():
    """A reconstruction whose walls stop 1.3 m above the floor, but for one: columns that
    reach 1.6 m (the traced outline's wall test) back 27 % of the outline. The walls-first
    outline takes walls reaching 1 m and finds the four corners."""
    points = room_scan(ceiling=False, height=2.5, furniture=3, seed=12)
    walls = (points[:, 2] > 0.05) & ~on_wall(points, 1, DEPTH, -1.0, WIDTH + 1)
    points = points[~(walls & (points[:, 2] > 1.3))]
    outline = detect_corners(points)
    assert not outline.approximate
    assert corner_errors(outline.corners, RECTANGLE).max() < 0.03, outline.corners
    assert len(outline.corners) == 4


def test_one_sided_depth_view_gives_a_partial_outline_on_its_far_wall():
    """One depth frame of a 7 m x 6 m room from 1.4 m above its floor (the view of
    tests/test_configurator/test_real_scan_geometry.py): the far wall and the floor in front of it.
    Before, an approximate floor (the points' bounding rectangle); now a partial outline whose far
    edge is the far wall, holding the points."""
    room = room_scan(width=7.0, depth=6.0, furniture=5, seed=4)
    view = depth_view(room, np.array([3.5, 0.3, 1.4]))
    outline = room_outline(view)
    assert not outline.approximate
    assert any(note.startswith('partial outline') for note in outline.notes)
    far = outline.corners[outline.corners[:, 1] > 4.0]
    assert len(far) == 2 and np.abs(far[:, 1] - (6.0 - 0.3)).max() < 0.02, outline.corners
    assert first_self_crossing(outline.corners) is None
    held = points_in_polygon(view[:, :2], outline.corners) | \
        (distance_to_polygon(view[:, :2], outline.corners) < 0.05)
    assert held.mean() > 0.95


def test_l_shaped_room_seen_from_one_side_keeps_its_walls_and_fills_the_unseen_notch():
    """An L room seen by one depth camera in the corner of its upper arm, looking into the
    lower arm: the lower arm's walls and the inner walls are seen, the floor near the camera
    and the walls beside and behind it are not. Before, the outline followed the view's
    occluded edges (18 corners); now it runs along the seen walls through the reflex corner
    and closes along the points' extent."""
    camera, look = np.array([0.5, 5.5, 1.4]), np.array([5.0, 0.5])
    view = occluded_view(l_room_scan(), camera, look)
    outline = room_outline(view)
    assert not outline.approximate
    seen_corners = in_view(L_ROOM[[3, 4, 5]], camera, look)  # (4, 3), (7, 3), (7, 0)
    assert corner_errors(outline.corners, seen_corners).max() < 0.03, outline.corners
    assert len(outline.corners) <= 8, outline.corners
    # every edge runs along the room's walls, none along the view's slanted sides
    along_x = np.diff(in_view(np.array([[0.0, 0.0], [1.0, 0.0]]), camera, look), axis=0)[0]
    edges = np.roll(outline.corners, -1, axis=0) - outline.corners
    edges /= np.linalg.norm(edges, axis=1, keepdims=True)
    sines = np.abs(edges[:, 0] * along_x[1] - edges[:, 1] * along_x[0])
    assert np.minimum(sines, np.abs(edges @ along_x)).max() < 0.01, outline.corners


def test_wall_planes_are_the_walls_not_scattered_points():
    """Two walls of 3 m (400 points per metre) and 2,000 points scattered over the room:
    two planes, each backing its wall's length."""
    rng = np.random.default_rng(0)
    wall_x = np.column_stack([rng.normal(0.0, 0.005, 1200), rng.uniform(0.0, 3.0, 1200)])
    wall_y = np.column_stack([rng.uniform(0.0, 3.0, 1200), rng.normal(4.0, 0.005, 1200)])
    scattered = rng.uniform([0.0, 0.0], [3.0, 4.0], (2000, 2))
    walls = np.vstack([wall_x, wall_y, scattered])
    across_x, across_y = wall_planes(walls, 0), wall_planes(walls, 1)
    assert len(across_x) == 1 and len(across_y) == 1
    assert across_x[0].offset == pytest.approx(0.0, abs=0.005)
    assert across_y[0].offset == pytest.approx(4.0, abs=0.005)
    assert across_x[0].length == pytest.approx(3.0, abs=0.15)


def test_walled_outline_fills_a_notch_no_wall_backs_but_not_a_walled_corner():
    """A plan footprint: a 6 m x 5 m rectangle without its lower right 2 m x 2 m corner. With
    walls on the corner's two inner sides it is an L room (6 corners); without them the
    missing corner is a notch of the view and is filled (4 corners)."""
    rng = np.random.default_rng(1)
    floor = rng.uniform([0, 0], [6, 5], (60_000, 2))
    floor = floor[~((floor[:, 0] > 4) & (floor[:, 1] < 2))]
    outer = [np.column_stack([rng.normal(0, 0.005, 2000), rng.uniform(0, 5, 2000)]),
             np.column_stack([rng.uniform(0, 6, 2000), rng.normal(5, 0.005, 2000)])]
    inner = [np.column_stack([rng.normal(4, 0.005, 800), rng.uniform(0, 2, 800)]),
             np.column_stack([rng.uniform(4, 6, 800), rng.normal(2, 0.005, 800)])]
    params, tuning = CornerParams(), WallEvidenceParams()
    walled = walled_outline(floor, np.vstack(outer + inner), params, tuning)
    assert walled is not None and len(walled.corners) == 6
    notched = walled_outline(floor, np.vstack(outer), params, tuning)
    assert notched is not None and len(notched.corners) == 4
    assert corner_errors(notched.corners, np.array([[6.0, 0.0]])).max() < 0.1
    assert math.isclose(notched.held, 1.0, abs_tol=0.01)


def test_real_scans_benchmark_outlines_every_scan_of_a_folder_and_draws_it(tmp_path):
    """``benchmarks/bench_corners.py --real DIR --views DIR`` on a folder holding the
    reconstruction with walls missing (PLY), a one-sided depth view (PCD) and files that are
    no scans: one line per scan, both outlined on their walls as partial outlines, a top
    view of each."""
    scans, views = tmp_path / 'scans', tmp_path / 'views'
    scans.mkdir()
    write_scan(scans / 'room.ply', walls_missing_scan())
    room = room_scan(width=7.0, depth=6.0, furniture=5, seed=4)
    write_scan(scans / 'view.pcd', depth_view(room, np.array([3.5, 0.3, 1.4])))
    (scans / 'view.labels.json').write_text('{}')
    (scans / 'README.md').write_text('scans\n')
    result = subprocess.run(
        [sys.executable, 'benchmarks/bench_corners.py', '--real', str(scans), '--views',
         str(views)], cwd=REPO, capture_output=True, text=True, check=False,
        env={**os.environ, 'PYTHONPATH': str(REPO)})
    assert result.returncode == 0, result.stderr
    lines = result.stdout.strip().splitlines()
    assert re.fullmatch(r'room\.ply +4 partial +\d+%', lines[-3]), lines
    assert re.fullmatch(r'view\.pcd +\d+ partial +\d+%', lines[-2]), lines
    assert re.fullmatch(r'corners, real scans: 2 of 2 outlined on their walls \(2 partial\), '
                        r'0 approximate floors; corners per outline 4-\d+', lines[-1]), lines
    assert sorted(path.name for path in views.iterdir()) == ['room.ply.png', 'view.pcd.png']
    assert all(path.read_bytes()[:4] == b'\x89PNG' for path in views.iterdir())
