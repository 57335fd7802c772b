"""Fusion of test-time-augmentation passes (projects/synthdet/core/box_fusion.py) and the 3D IoU
it groups by, against hand-computed cases and a brute-force reference."""
import pytest
import torch

from projects.synthdet.core.box_fusion import fuse_passes
from projects.synthdet.core.box_ops import pairwise_iou_3d


def reference_iou_3d(a, b):
    """3D IoU of two (x, y, z, dx, dy, dz) boxes with Python floats."""
    inter = 1.0
    for axis in range(3):
        low = max(a[axis] - a[axis + 3] / 2, b[axis] - b[axis + 3] / 2)
        high = min(a[axis] + a[axis + 3] / 2, b[axis] + b[axis + 3] / 2)
        inter *= max(high - low, 0.0)
    return inter / (a[3] * a[4] * a[5] + b[3] * b[4] * b[5] - inter)


def test_pairwise_iou_3d_matches_reference():
    generator = torch.Generator().manual_seed(3)
    boxes = torch.cat((torch.rand(12, 3, generator=generator, dtype=torch.float64) * 2,
                       0.3 + torch.rand(12, 3, generator=generator, dtype=torch.float64)),
                      dim=1)
    iou = pairwise_iou_3d(boxes, boxes[:7])
    assert iou.shape == (12, 7)
    for i in range(12):
        for j in range(7):
            assert iou[i, j].item() == pytest.approx(
                reference_iou_3d(boxes[i].tolist(), boxes[j].tolist()), abs=1e-12)
    # a box on a table top touches it but does not overlap it in 3D
    table, printer = [0, 0, 0.4, 1.6, 0.8, 0.8], [0, 0, 1.05, 0.5, 0.5, 0.5]
    assert pairwise_iou_3d(torch.tensor([table]), torch.tensor([printer])).item() == pytest.approx(
        0, abs=1e-6)


def test_an_object_every_pass_finds_keeps_its_score_and_gets_the_weighted_mean_box():
    boxes = torch.tensor([[0.0, 0, 0.5, 1, 1, 1], [0.1, 0, 0.5, 1, 1, 1], [5, 5, 0.5, 1, 1, 1]])
    scores = torch.tensor([0.9, 0.3, 0.6])
    fused_boxes, fused_scores, labels = fuse_passes(boxes, scores, torch.tensor([2, 2, 2]),
                                                    torch.tensor([0, 1, 1]), 2, 0.5)
    order = torch.argsort(fused_scores, descending=True)
    # the first object: found by both passes, mean of 0.9 and 0.3; the box weighted 3:1
    assert fused_scores[order].tolist() == pytest.approx([0.6, 0.3])
    assert fused_boxes[order[0]].tolist() == pytest.approx([0.025, 0, 0.5, 1, 1, 1])
    # the second: pass 1 alone, its score halved
    assert fused_boxes[order[1]].tolist() == pytest.approx([5, 5, 0.5, 1, 1, 1])
    assert labels.tolist() == [2, 2]


def test_classes_and_boxes_below_the_iou_stay_apart_and_a_pass_counts_once():
    boxes = torch.tensor([
        [0.0, 0, 0.5, 1, 1, 1],  # pass 0, class 0
        [0.0, 0, 0.5, 1, 1, 1],  # pass 1, class 1: another class, its own group
        [0.6, 0, 0.5, 1, 1, 1],  # pass 1, class 0: IoU 0.4 / 1.6 = 0.25 with the first
        [0.05, 0, 0.5, 1, 1, 1],  # pass 0 again, class 0: a duplicate of its own pass
    ])
    scores = torch.tensor([0.8, 0.7, 0.6, 0.4])
    fused_boxes, fused_scores, labels = fuse_passes(boxes, scores, torch.tensor([0, 1, 0, 0]),
                                                    torch.tensor([0, 1, 1, 0]), 2, 0.5)
    assert labels.tolist() == [0, 0, 1]
    # class 0: {0.8, 0.4 from pass 0} -> 0.8 / 2; the shifted box alone -> 0.6 / 2
    assert fused_scores.tolist() == pytest.approx([0.4, 0.3, 0.35])
    assert fused_boxes[0, 0].item() == pytest.approx((0.8 * 0 + 0.4 * 0.05) / 1.2)
    # with a looser threshold the shifted box joins the first group
    _, scores_loose, _ = fuse_passes(boxes, scores, torch.tensor([0, 1, 0, 0]),
                                     torch.tensor([0, 1, 1, 0]), 2, 0.2)
    assert scores_loose.tolist() == pytest.approx([0.7, 0.35])


def test_a_single_pass_keeps_every_box_that_nms_kept():
    boxes = torch.tensor([[0.0, 0, 0.5, 1, 1, 1], [3, 0, 0.5, 1, 1, 1]])
    fused_boxes, fused_scores, labels = fuse_passes(boxes, torch.tensor([0.2, 0.9]),
                                                    torch.tensor([1, 1]), torch.tensor([0, 0]), 1,
                                                    0.5)
    assert fused_scores.tolist() == pytest.approx([0.9, 0.2])
    torch.testing.assert_close(fused_boxes, boxes[[1, 0]])


def test_no_boxes_and_mismatched_inputs():
    boxes, scores, labels = fuse_passes(
        torch.zeros((0, 6)), torch.zeros(0), torch.zeros(0, dtype=torch.long),
        torch.zeros(0, dtype=torch.long), 4, 0.5)
    assert boxes.shape == (0, 6) and scores.shape == (0, ) and labels.shape == (0, )
    with pytest.raises(ValueError, match='differ in length'):
        fuse_passes(
            torch.zeros((2, 6)), torch.zeros(1), torch.zeros(2, dtype=torch.long),
            torch.zeros(2, dtype=torch.long), 1, 0.5)
