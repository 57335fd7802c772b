"""The measured fine-tune on corrected rooms (benchmarks/bench_teach.py): how it separates
overlapping true boxes and plans a correction, and one whole run at a tiny scale through the
real scan2cad, FreeCAD, labels, converter, Runner and evaluation (two training iterations)."""
from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from benchmarks.bench_teach import SEPARATION, correction_plan, separate_boxes
from configurator.labels import check_overlaps
from synthdet.geometry import box_corners_xy

REPO = Path(__file__).resolve().parents[1]
CLASSES = ['table', 'chair', 'sofa', 'yumi', '3dprinter']
NUMBER = r'(\d+\.\d+)'
HEADLINE = re.compile(rf'teach: held-out recall {NUMBER} -> {NUMBER} at IoU 0\.25, false '
                      rf'positives per room {NUMBER} -> {NUMBER}, area 9 mAP@0\.25 {NUMBER} -> '
                      rf'{NUMBER} \(2 training rooms, 1 held-out rooms, fine-tune {NUMBER} min\)')


def box(name: str, center, size, yaw: float = 0.0, label: str = '') -> dict:
    return {
        'class': name,
        'center': list(center),
        'size': list(size),
        'yaw': yaw,
        'label': label or name
    }


def extent(item: dict, axis: int) -> tuple[float, float]:
    """The box's interval along world axis 0 (x), 1 (y) or 2 (z)."""
    if axis == 2:
        half = item['size'][2] / 2.0
        return item['center'][2] - half, item['center'][2] + half
    corners = box_corners_xy(item['center'], item['size'], item['yaw'])[:, axis]
    return float(corners.min()), float(corners.max())


def test_overlapping_true_boxes_are_cut_apart_at_their_smallest_overlap():
    # two chairs sharing 0.1 m along x (and more along y and z), the second turned 90 degrees
    first = box('chair', (0.0, 0.0, 0.4), (0.6, 0.5, 0.8), label='chair 1')
    second = box('chair', (0.4, 0.1, 0.45), (0.6, 0.4, 0.9), math.pi / 2, 'chair 2')
    apart, cuts = separate_boxes([first, second])
    assert len(cuts) == 1 and 'along x' in cuts[0]
    assert extent(apart[1], 0)[0] - extent(apart[0], 0)[1] == pytest.approx(SEPARATION)
    assert extent(apart[0], 0)[0] == pytest.approx(-0.3)  # the far sides stay
    assert extent(apart[1], 0)[1] == pytest.approx(0.6)
    assert apart[1]['size'][0] == second['size'][0]  # its width is along x once turned
    assert apart[0]['center'][1:] == first['center'][1:] and apart[1]['yaw'] == second['yaw']
    check_overlaps(apart, 'separated')  # what `labels` accepts
    with pytest.raises(Exception, match='overlap'):
        check_overlaps([first, second], 'as labelled')
    # a desk top above a table: cut along z, the smaller overlap
    table = box('table', (0.0, 0.0, 0.35), (1.0, 1.0, 0.7))
    top = box('table', (0.2, 0.0, 0.72), (1.0, 1.0, 0.1))
    (low, high), _ = separate_boxes([table, top])
    assert extent(high, 2)[0] - extent(low, 2)[1] == pytest.approx(SEPARATION)
    assert extent(low, 2)[0] == pytest.approx(0.0) and extent(high, 2)[1] == pytest.approx(0.77)
    with pytest.raises(ValueError, match='not parallel'):
        separate_boxes([first, box('sofa', (0.2, 0.0, 0.4), (1.0, 0.5, 0.8), 0.3)])
    assert separate_boxes([first, box('table', (2.0, 0.0, 0.4), (1.0, 1.0, 0.8))])[1] == []


def test_the_correction_keeps_matched_parts_deletes_the_rest_and_adds_the_missed():
    truth = [
        box('chair', (1.0, 1.0, 0.45), (0.5, 0.5, 0.9)),
        box('table', (3.0, 1.0, 0.375), (1.4, 0.8, 0.75)),
        box('chair', (5.0, 1.0, 0.45), (0.5, 0.5, 0.9))
    ]
    parts = [
        dict(box('chair', (1.1, 1.0, 0.45), (0.5, 0.5, 0.9)), name='Chair001'),
        dict(box('sofa', (3.0, 1.0, 0.4), (1.8, 0.9, 0.8)), name='Sofa001'),  # wrong class
        dict(box('chair', (8.0, 1.0, 0.45), (0.5, 0.5, 0.9)), name='Chair002'),  # phantom
        dict(box('chair', (1.0, 1.1, 0.45), (0.5, 0.5, 0.9)), name='Chair003')
    ]  # second
    plan = correction_plan(parts, truth)
    assert [(item['name'], item['box']['center'])
            for item in plan['edit']] == [('Chair001', [1.0, 1.0, 0.45])]
    assert [item['center'] for item in plan['add']] == [[3.0, 1.0, 0.375], [5.0, 1.0, 0.45]]
    assert all(set(item) == {'class', 'center', 'size', 'yaw'} for item in plan['add'])
