"""One box for an object detected as several (projects/synthdet/inference/fragments.py): the
merge rule on hand-made detections, and the rule read from the configs."""
import numpy as np
import pytest

from projects.synthdet.bootstrap import load_config
from projects.synthdet.inference.fragments import (FragmentRule, fragment_rule_from_config,
                                                   merge_fragments)
from projects.synthdet.inference.windows import Detections

CLASSES = ['table', 'chair', 'sofa', 'yumi', '3dprinter']
RULE = FragmentRule(('table', 'sofa'), 0.3)


def detections(rows: list[tuple]) -> Detections:
    """Detections of ``(class, score, (x0, y0, x1, y1), yaw)`` rows, 0.8 m high on the floor."""
    boxes = [[(x0 + x1) / 2, (y0 + y1) / 2, 0.4, x1 - x0, y1 - y0, 0.8, yaw]
             for _, _, (x0, y0, x1, y1), yaw in rows]
    return Detections(np.array(boxes, dtype=np.float64).reshape(-1, 7),
                      np.array([row[1] for row in rows], dtype=np.float64),
                      np.array([CLASSES.index(row[0]) for row in rows], dtype=np.int64))


def footprints(found: Detections) -> list[tuple]:
    """``(class, score, x0, y0, x1, y1)`` of each box, rounded to the millimetre."""
    return [(CLASSES[label], score, *np.round(
        [box[0] - box[3] / 2, box[1] - box[4] / 2, box[0] + box[3] / 2, box[1] + box[4] / 2],
        3).tolist()) for box, score, label in zip(found.boxes, found.scores, found.labels)]


def test_the_pieces_of_an_l_shaped_sofa_become_one_box():
    """Three sofa boxes along the two arms of an L: the long arm absorbs the corner piece, then,
    grown, the short arm, which overlaps the long arm alone too little."""
    found = merge_fragments(
        detections([
            ('sofa', 0.6, (0.0, 0.0, 2.4, 0.9), 0.0),  # the long arm
            ('sofa', 0.4, (1.8, 0.0, 2.8, 1.2), 0.0),  # the corner: 0.45 of it inside
            ('sofa', 0.35, (2.0, 0.6, 2.9, 2.0), 0.0),  # the short arm: 0.38 in the grown box
        ]), CLASSES, RULE, 0.3)
    assert footprints(found) == [('sofa', 0.6, 0.0, 0.0, 2.9, 2.0)]
    # without the corner piece, the short arm (0.1 of it in the long arm) stays a box of its own
    assert len(merge_fragments(detections([
        ('sofa', 0.6, (0.0, 0.0, 2.4, 0.9), 0.0),
        ('sofa', 0.35, (2.0, 0.6, 2.9, 2.0), 0.0)]), CLASSES, RULE, 0.3).scores) == 2


def test_separate_objects_other_classes_and_low_scores_stay_as_they_are():
    rows = [
        ('table', 0.9, (0.0, 0.0, 1.6, 0.8), 0.0),
        ('table', 0.8, (1.5, 0.0, 3.1, 0.8), 0.0),  # pushed against it: 1/16 of it inside
        ('chair', 0.7, (0.2, 0.2, 0.7, 0.7), 0.0),  # a chair under the table: another class
        ('chair', 0.6, (0.3, 0.3, 0.8, 0.8), 0.0),  # chairs are not merged
        ('sofa', 0.5, (5.0, 5.0, 6.0, 7.0), np.pi / 2),  # turned a quarter: kept with its yaw
        ('table', 0.2, (0.1, 0.1, 1.5, 0.7), 0.0),  # below the threshold: no fragment
    ]
    before = detections(rows)
    found = merge_fragments(before, CLASSES, RULE, 0.3)
    assert np.array_equal(found.boxes, before.boxes)
    assert np.array_equal(found.scores, before.scores)


def test_a_fragment_inside_a_larger_box_goes_and_the_order_is_by_score():
    found = merge_fragments(
        detections([
            ('table', 0.4, (0.0, 0.0, 2.0, 1.0), 0.0),
            ('chair', 0.5, (4.0, 4.0, 4.5, 4.5), 0.0),
            ('table', 0.45, (0.5, 0.2, 1.0, 0.6), 0.0),  # a piece of the table, scoring higher
        ]), CLASSES, RULE, 0.3)
    assert footprints(found) == [('chair', 0.5, 4.0, 4.0, 4.5, 4.5),
                                 ('table', 0.45, 0.0, 0.0, 2.0, 1.0)]
    assert np.all(found.boxes[:, 6] == 0.0)


def test_the_configs_carry_the_rule_and_a_bad_rule_is_refused():
    rule = fragment_rule_from_config(load_config('configs/tr3d/exp2_cpu.py'))
    assert rule == FragmentRule(('table', 'sofa'), 0.3)
    assert fragment_rule_from_config({}) is None
    with pytest.raises(ValueError, match=r'fragment_merge.min_share 1.5: expected a number'):
        fragment_rule_from_config({'fragment_merge': {'classes': ['sofa'], 'min_share': 1.5}})
    with pytest.raises(ValueError, match=r'fragment_merge.classes .*: expected a list of class'):
        fragment_rule_from_config({'fragment_merge': {'classes': 'sofa', 'min_share': 0.3}})
