"""Known objects of an earlier, corrected scan found again in a later one
(projects/synthdet/inference/known_objects.py), on L-shaped rooms the tests build: the
registration across quarter turns and shifts, objects that stayed, moved away or are new, and a
different room refused."""
from __future__ import annotations

import numpy as np
import pytest

from projects.synthdet.inference.known_objects import (RegistrationError, move_boxes,
                                                       quarter_turn, register,
                                                       with_known_objects)
from tests.room_scans import make_room, outside_box, sample_box

DENSITY = 2000.0  # points per m^2 of the objects' faces


def box_dict(name: str, center, size, yaw: float = 0.0) -> dict:
    return {'class': name, 'center': list(center), 'size': list(size), 'yaw': yaw}


def scene(boxes: list[dict], seed: int, shape: str = 'L') -> np.ndarray:
    """A room of ``shape`` (axis-aligned, floor at 0) holding the boxes; points ``(N, 3)``."""
    room = make_room(shape, n_points=60_000, seed=3, furniture=0, openings=False, rotate=False)
    points = room.points[:, :3] - [0.0, 0.0, room.floor_z]
    rng = np.random.default_rng(seed)
    parts = []
    for box in boxes:
        center = np.asarray(box['center'])
        as_tuple = (center[:2], np.asarray(box['size']), box['yaw'], False)
        sampled = sample_box(as_tuple, DENSITY, rng)[:, :3]
        parts.append(sampled + [0.0, 0.0, center[2] - box['size'][2] / 2])
        points = outside_box(points, as_tuple, margin=0.0)
    return np.concatenate([points, *parts])


def turned(points: np.ndarray, turns: int, shift) -> tuple[np.ndarray, np.ndarray]:
    matrix = np.eye(4)
    matrix[:3, :3] = quarter_turn(turns)
    matrix[:2, 3] = shift
    return points @ matrix[:3, :3].T + matrix[:3, 3], matrix


def room_boxes(polygon_points: np.ndarray) -> tuple[dict, dict]:
    """A table and a chair inside the room, 1.5 m apart."""
    low = polygon_points[:, :2].min(0)
    table = box_dict('table', [low[0] + 1.5, low[1] + 1.5, 0.375], [1.2, 0.8, 0.75])
    chair = box_dict('chair', [low[0] + 3.0, low[1] + 1.5, 0.45], [0.5, 0.5, 0.9], 0.3)
    return table, chair


@pytest.mark.parametrize('turns, shift', [(0, (0.4, -0.3)), (1, (2.0, 0.5)), (3, (-1.2, 0.7))])
def test_two_scans_of_one_room_register_across_a_quarter_turn(turns, shift):
    empty = scene([], seed=0)
    earlier = scene(list(room_boxes(empty)), seed=1)
    later, truth = turned(scene(list(room_boxes(empty)), seed=2), turns, shift)
    registration = register(earlier, later)
    assert registration.overlap > 0.8
    np.testing.assert_allclose(registration.transform[:3, :3], truth[:3, :3], atol=0.02)
    np.testing.assert_allclose(registration.transform[:3, 3], truth[:3, 3], atol=0.03)


def test_a_different_room_is_refused():
    rect = make_room('T', n_points=60_000, seed=8, furniture=0, openings=False, rotate=False)
    with pytest.raises(RegistrationError, match='not two scans of the same room'):
        register(scene([], seed=0), rect.points[:, :3] - [0.0, 0.0, rect.floor_z])


def test_objects_that_stayed_are_found_again_and_only_what_changed_is_detected():
    empty = scene([], seed=0)
    table, chair = room_boxes(empty)
    low = empty[:, :2].min(0)
    sofa = box_dict('sofa', [low[0] + 1.5, low[1] + 3.5, 0.4], [2.0, 0.9, 0.8])
    earlier = scene([table, chair], seed=1)
    # the later scan: the table stayed, the chair is gone, a sofa is new; a quarter turn away
    later, matrix = turned(scene([table, sofa], seed=2), 1, (1.0, -2.0))
    detections = [
        dict(move_boxes([table], matrix)[0], score=0.6),  # the table, which the labels hold
        dict(move_boxes([sofa], matrix)[0], score=0.7),  # the new sofa
        # a box on the unchanged floor by the wall, where the user labelled nothing
        dict(move_boxes([box_dict('chair', [low[0] + 0.5, low[1] + 0.5, 0.45], [0.5, 0.5, 0.9])],
                        matrix)[0], score=0.5),
    ]
    boxes, counts = with_known_objects(detections, [table, chair], later, earlier, matrix)
    assert counts == {'known': 2, 'found_again': 1, 'detections': 3, 'detections_kept': 1}
    assert [box['class'] for box in boxes] == ['table', 'sofa']
    np.testing.assert_allclose(boxes[0]['center'], move_boxes([table], matrix)[0]['center'],
                               atol=1e-9)
    assert boxes[0]['score'] > 0.9 and boxes[1]['score'] == 0.7
    assert boxes[0]['yaw'] == pytest.approx(np.pi / 2)


def test_boxes_move_with_the_matrix():
    matrix = np.eye(4)
    matrix[:3, :3] = quarter_turn(1)
    matrix[:3, 3] = [1.0, 2.0, 0.0]
    moved = move_boxes([box_dict('table', [1.0, 0.0, 0.4], [1.0, 0.5, 0.8], 0.2)], matrix)[0]
    np.testing.assert_allclose(moved['center'], [1.0, 3.0, 0.4], atol=1e-12)
    assert moved['yaw'] == pytest.approx(0.2 + np.pi / 2) and moved['size'] == [1.0, 0.5, 0.8]
