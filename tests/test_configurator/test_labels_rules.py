"""The rules of ``python -m configurator labels`` on points and boxes made up here: which box a
point belongs to (overlapping boxes included), the annotation of a box whose points all went to
others, annotation names, and the room outline's structure elements."""
import math

import numpy as np
import pytest

from configurator.labels import (BOX_MARGIN, LabelsInputError, background_elements,
                                 instance_names, point_owners, shadowed_boxes, write_s3dis_room)
from synthdet.scan_io import read_scan


def box(label: str, center, size, yaw: float = 0.0) -> dict:
    return {
        'class': 'chair',
        'label': label,
        'center': list(center),
        'size': list(size),
        'yaw': yaw
    }


def test_points_are_given_to_the_nearest_box_and_a_box_off_the_scan_refused():
    table = box('table 1', [0.0, 0.0, 0.4], [1.0, 1.0, 0.8])
    robot = box('yumi 1', [0.0, 0.0, 1.1], [0.4, 0.4, 0.6])
    points = np.array([
        [0.0, 0.0, 0.0],  # the floor under the table: nobody's
        [0.3, 0.3, 0.8],  # on the table top: the table's
        [0.0, 0.0, 0.8 + 0.0004],  # a robot foot point within the clearance: the table's
        [0.1, 0.1, 0.802],  # the robot's: inside it, 2 mm above the table
        [0.5 + BOX_MARGIN / 2, 0.0, 0.5],  # just outside the table's side: the table's
        [0.5 + 2 * BOX_MARGIN, 0.0, 0.5],  # farther out: nobody's
    ])
    assert point_owners(points, [table, robot], 'doc').tolist() == [-1, 0, 0, 1, 0, -1]
    empty = box('chair 3', [5.0, 5.0, 0.4], [0.5, 0.5, 0.8])
    with pytest.raises(LabelsInputError, match=r"^doc: 'chair 3' holds no scan point"):
        point_owners(points, [table, empty], 'doc')


def test_a_point_inside_overlapping_boxes_belongs_to_the_smallest():
    """A chair pushed half under a table: its seat and the table top above it lie in both
    boxes and are the chair's; the table keeps its other half."""
    table = box('table 1', [0.0, 0.0, 0.375], [1.4, 0.8, 0.75])
    chair = box('chair 1', [0.0, 0.4, 0.45], [0.5, 0.5, 0.9], math.pi / 2)
    points = np.array([
        [0.0, 0.3, 0.45],  # the seat, under the table top: in both, the chair's
        [0.1, 0.35, 0.75],  # the table top over the seat: in both, the chair's
        [0.0, -0.3, 0.75],  # the table top away from the chair: the table's
        [0.0, 0.6, 0.85],  # the backrest out from under the table: the chair's
        [0.6, 0.0, 0.2],  # a table leg: the table's
    ])
    for boxes, table_index, chair_index in (([table, chair], 0, 1), ([chair, table], 1, 0)):
        owners = point_owners(points, boxes, 'doc')
        assert owners.tolist() == [chair_index, chair_index, table_index, chair_index,
                                   table_index]
        assert shadowed_boxes(points, boxes, owners, 'doc') == ({}, [])


def test_a_box_whose_points_all_went_to_smaller_boxes_repeats_them_with_a_warning(
        tmp_path):
    table = box('table 1', [0.0, 0.0, 0.4], [1.0, 1.0, 0.8])
    twin = box('table 2', [0.0, 0.0, 0.4], [1.0, 1.0, 0.8], math.pi / 2)  # duplicated in place
    points = np.array([[0.0, 0.0, 0.8], [0.3, 0.2, 0.4], [3.0, 0.0, 0.4]])
    owners = point_owners(points, [table, twin], 'doc')
    assert owners.tolist() == [0, 0, -1]  # equal boxes: the first in document order
    repeated, warnings = shadowed_boxes(points, [table, twin], owners, 'doc')
    assert list(repeated) == [1] and repeated[1].tolist() == [0, 1]
    assert warnings == ["doc: every scan point of 'table 2' belongs to 'table 1': its "
                        'annotation file repeats those 2 points']
    elements = np.array(['table_1', 'table_1', 'clutter_1'], dtype=object)
    room = tmp_path / 'Area_1' / 'twin_1'
    write_s3dis_room(room, np.column_stack([points, np.zeros((3, 3))]), elements,
                     {'table_2': repeated[1]})
    assert read_scan(room / 'Annotations' / 'table_2.txt')[:, :3].tolist() == points[:2].tolist()
    assert read_scan(room / 'Annotations' / 'table_1.txt')[:, :3].tolist() == points[:2].tolist()
    assert len(read_scan(room / 'twin_1.txt')) == 3  # the room holds every point once


def test_annotation_names_are_numbered_per_class_and_safe_as_file_names():
    boxes = [box('table 1', [0, 0, 0], [1, 1, 1]), box('chair 1', [2, 0, 0], [1, 1, 1])]
    boxes[0]['class'] = 'table'
    boxes.append(dict(boxes[1], label='chair 2'))
    assert instance_names(boxes, 'doc') == ['table_1', 'chair_1', 'chair_2']
    for bad in ('../../escape', 'fork lift', 'pallet_rack', ''):
        boxes[1]['class'] = bad
        with pytest.raises(LabelsInputError, match=r"^doc: part 'chair 1' has class"):
            instance_names(boxes, 'doc')


def test_background_points_follow_the_room_outline():
    room = {
        'corners': [[0.0, 0.0], [0.0, 4.0], [5.0, 4.0], [5.0, 0.0]],
        'floor_z': 0.0,
        'ceiling_z': 3.0
    }
    points = np.array([[2.0, 2.0, 0.01], [2.0, 2.0, 2.98], [0.02, 2.0, 1.5], [2.0, 3.99, 1.5],
                       [5.0, 1.0, 1.0], [2.0, 2.0, 1.5]])
    assert background_elements(points, room).tolist() == [
        'floor_1', 'ceiling_1', 'wall_1', 'wall_2', 'wall_3', 'clutter_1'
    ]
    assert set(background_elements(points, None)) == {'clutter_1'}
