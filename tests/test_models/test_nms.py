"""Axis-aligned 3D NMS: torch CPU implementation, device dispatch and the arguments of mmcv's CUDA
kernel vs a brute-force reference."""
import pytest
import torch

from projects.synthdet.core import (axis_aligned_nms3d, axis_aligned_nms3d_cpu,
                                    mmcv_nms3d_arguments, multiclass_axis_aligned_nms3d,
                                    pairwise_bev_iou, uses_mmcv_kernel)


def reference_bev_iou(a, b):
    """BEV IoU of two (x, y, z, dx, dy, dz) boxes with Python floats (mmcv's iou_normal)."""
    left, right = max(a[0] - a[3] / 2, b[0] - b[3] / 2), min(a[0] + a[3] / 2, b[0] + b[3] / 2)
    low, high = max(a[1] - a[4] / 2, b[1] - b[4] / 2), min(a[1] + a[4] / 2, b[1] + b[4] / 2)
    inter = max(right - left, 0.0) * max(high - low, 0.0)
    return inter / max(a[3] * a[4] + b[3] * b[4] - inter, 1e-8)


def reference_nms(boxes, scores, iou_thr):
    """O(n^2) greedy NMS: highest score first (ties by index), drop boxes with IoU > iou_thr."""
    boxes, scores = boxes.tolist(), scores.tolist()
    order = sorted(range(len(scores)), key=lambda i: (-scores[i], i))
    keep = []
    for i in order:
        if all(reference_bev_iou(boxes[i], boxes[k]) <= iou_thr for k in keep):
            keep.append(i)
    return keep


def random_boxes(n, seed, extent=4.0):
    generator = torch.Generator().manual_seed(seed)
    centers = torch.rand(n, 3, generator=generator, dtype=torch.float64) * extent
    sizes = 0.2 + torch.rand(n, 3, generator=generator, dtype=torch.float64) * 1.5
    scores = torch.rand(n, generator=generator, dtype=torch.float64)
    return torch.cat((centers, sizes), dim=1).float(), scores.float()


@pytest.mark.parametrize('seed', range(6))
@pytest.mark.parametrize('iou_thr', [0.1, 0.25, 0.5, 0.7])
def test_cpu_nms_and_dispatcher_match_brute_force(seed, iou_thr):
    boxes, scores = random_boxes(60 + 20 * seed, seed)
    expected = reference_nms(boxes, scores, iou_thr)
    assert axis_aligned_nms3d_cpu(boxes, scores, iou_thr).tolist() == expected
    assert axis_aligned_nms3d(boxes, scores, iou_thr).tolist() == expected
    assert 0 < len(expected) < len(boxes)  # the case really suppresses something


def test_pairwise_bev_iou_matches_reference():
    boxes, _ = random_boxes(30, 7)
    iou = pairwise_bev_iou(boxes, boxes)
    for i in range(30):
        for j in range(30):
            assert iou[i, j].item() == pytest.approx(
                reference_bev_iou(boxes[i].tolist(), boxes[j].tolist()), abs=1e-5)


def test_overlap_ignores_height_like_mmcv():
    """Two boxes stacked in z with the same footprint overlap fully in BEV: one is suppressed."""
    boxes = torch.tensor([[0, 0, 0.5, 1, 1, 1], [0, 0, 3.0, 1, 1, 1.0]])
    assert axis_aligned_nms3d(boxes, torch.tensor([0.9, 0.8]), 0.5).tolist() == [0]


def test_yaw_column_is_ignored_and_result_in_score_order():
    boxes, scores = random_boxes(50, 11)
    with_yaw = torch.cat((boxes, torch.rand(50, 1)), dim=1)
    keep = axis_aligned_nms3d(with_yaw, scores, 0.3)
    assert keep.tolist() == axis_aligned_nms3d(boxes, scores, 0.3).tolist()
    assert torch.all(scores[keep][:-1] >= scores[keep][1:])


def test_empty_and_bad_inputs():
    assert axis_aligned_nms3d(torch.zeros((0, 6)), torch.zeros(0), 0.5).numel() == 0
    with pytest.raises(ValueError, match='boxes must be'):
        axis_aligned_nms3d(torch.zeros((3, 5)), torch.zeros(3), 0.5)
    with pytest.raises(ValueError, match='scores must be'):
        axis_aligned_nms3d(torch.zeros((3, 6)), torch.zeros(4), 0.5)


def test_dispatch_decision_by_device():
    assert uses_mmcv_kernel(torch.device('cuda'))
    assert uses_mmcv_kernel(torch.device('cuda', 1))
    assert not uses_mmcv_kernel(torch.device('cpu'))
    assert not uses_mmcv_kernel(torch.zeros(1).device)


@pytest.mark.parametrize('columns', [6, 7])
def test_mmcv_kernel_arguments_layout_and_padding(columns):
    """What the CUDA branch hands to ``nms3d_normal``: (N, 7) boxes (x, y, z, dx, dy, dz, yaw),
    a zero yaw column appended to (N, 6) boxes, a given yaw kept (the kernel ignores it),
    contiguous float32 tensors and the threshold as a float."""
    boxes, scores = random_boxes(20, 5)
    given = torch.cat((boxes, torch.rand(20, 1)), dim=1) if columns == 7 else boxes
    given = given.double().t().contiguous().t()  # float64 and not contiguous, as a caller may
    kernel_boxes, kernel_scores, kernel_thr = mmcv_nms3d_arguments(given, scores.double(), 0.25)
    assert kernel_boxes.shape == (20, 7) and kernel_boxes.dtype == torch.float32
    assert kernel_boxes.is_contiguous() and kernel_scores.is_contiguous()
    assert torch.equal(kernel_boxes[:, :6], boxes)  # centre and size columns unchanged
    expected_yaw = given[:, 6].float() if columns == 7 else torch.zeros(20)
    assert torch.equal(kernel_boxes[:, 6], expected_yaw)
    assert kernel_scores.dtype == torch.float32 and torch.equal(kernel_scores, scores)
    assert type(kernel_thr) is float and kernel_thr == 0.25
    empty_boxes, empty_scores, _ = mmcv_nms3d_arguments(torch.zeros((0, 6)), torch.zeros(0), 0.5)
    assert empty_boxes.shape == (0, 7) and empty_scores.shape == (0, )


@pytest.mark.parametrize('iou_thr', [0.25, 0.5])
def test_mmcv_kernel_arguments_give_the_reference_result(iou_thr):
    """The kernel's semantics (BEV IoU of the centre-size columns, yaw ignored, highest score
    first) applied to the prepared arguments give the reference result of the original boxes."""
    boxes, scores = random_boxes(80, 9)
    kernel_boxes, kernel_scores, kernel_thr = mmcv_nms3d_arguments(boxes, scores, iou_thr)
    assert reference_nms(kernel_boxes[:, :6], kernel_scores, kernel_thr) == \
        reference_nms(boxes, scores, iou_thr)


@pytest.mark.skipif(not torch.cuda.is_available(), reason='needs CUDA: runs mmcv nms3d_normal')
@pytest.mark.parametrize('columns', [6, 7])
def test_cuda_branch_matches_brute_force(columns):
    boxes, scores = random_boxes(120, 4)
    given = torch.cat((boxes, torch.rand(120, 1)), dim=1) if columns == 7 else boxes
    keep = axis_aligned_nms3d(given.cuda(), scores.cuda(), 0.3)
    assert keep.is_cuda
    assert keep.cpu().tolist() == reference_nms(boxes, scores, 0.3)


@pytest.mark.parametrize('seed', range(3))
def test_multiclass_nms_matches_per_class_brute_force(seed):
    boxes, _ = random_boxes(80, 100 + seed)
    scores = torch.rand(80, 4, generator=torch.Generator().manual_seed(seed))
    score_thr, iou_thr = 0.3, 0.4
    kept_boxes, kept_scores, labels = multiclass_axis_aligned_nms3d(boxes, scores, score_thr,
                                                                    iou_thr)
    expected = []
    for label in range(4):
        candidates = torch.nonzero(scores[:, label] > score_thr).flatten()
        keep = reference_nms(boxes[candidates], scores[candidates, label], iou_thr)
        expected += [(label, candidates[k].item()) for k in keep]
    assert labels.tolist() == [label for label, _ in expected]
    assert torch.equal(kept_boxes, boxes[[index for _, index in expected]])
    assert torch.equal(kept_scores, scores[[index for _, index in expected],
                                           [label for label, _ in expected]])


def test_multiclass_nms_nothing_above_threshold():
    boxes, _ = random_boxes(10, 3)
    kept_boxes, kept_scores, labels = multiclass_axis_aligned_nms3d(boxes,
                                                                    torch.full((10, 3), 0.005),
                                                                    0.01, 0.5)
    assert kept_boxes.shape == (0, 6) and kept_scores.shape == (0, ) and labels.dtype == torch.long
