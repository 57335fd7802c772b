"""``tools/test.py --show-dir``: one top-view picture per test scan with truth and predictions.

:class:`TopViewHook` draws every test sample with the project's renderer
(``synthdet.topview.draw_top_view``): the converted scan's points colored by class (from its
``semantic_mask``), the ground-truth boxes solid and the predictions with a score of at least
``score_thr`` dashed, in the frame of the info pickles. In a distributed test each process
draws the samples it evaluates.
"""
from pathlib import Path
from typing import Sequence

from mmdet3d.registry import HOOKS
from mmdet3d.structures import BaseInstance3DBoxes, Det3DDataSample
from mmengine.hooks import Hook

from synthdet.room_data import Box, load_scan
from synthdet.topview import draw_top_view


def instance_boxes(boxes: BaseInstance3DBoxes,
                   labels: Sequence[int],
                   classes: Sequence[str],
                   scores: Sequence[float] | None = None) -> list[Box]:
    """mmdet3d boxes (gravity centre, size, yaw) with class indices as :class:`Box` records."""
    centers, sizes = boxes.gravity_center.tolist(), boxes.dims.tolist()
    yaws = boxes.yaw.tolist()
    return [
        Box(classes[int(label)], tuple(center), tuple(size), float(yaw),
            None if scores is None else float(scores[i]))
        for i, (label, center, size, yaw) in enumerate(zip(labels, centers, sizes, yaws))
    ]


@HOOKS.register_module()
class TopViewHook(Hook):
    """Save ``<out_dir>/<scan>.png`` for every test sample (see the module doc).

    Args:
        out_dir: folder of the pictures (created).
        score_thr: predictions below this score are not drawn.
    """

    def __init__(self, out_dir: str, score_thr: float = 0.1):
        self.out_dir = Path(out_dir)
        self.score_thr = score_thr

    def before_test(self, runner) -> None:
        self.out_dir.mkdir(parents=True, exist_ok=True)

    def after_test_iter(self,
                        runner,
                        batch_idx: int,
                        data_batch: dict | None = None,
                        outputs: Sequence[Det3DDataSample] | None = None) -> None:
        classes = runner.test_dataloader.dataset.metainfo['classes']
        for sample in outputs or []:
            truth = sample.eval_ann_info
            pred = sample.pred_instances_3d
            keep = pred.scores_3d >= self.score_thr
            gt_boxes = instance_boxes(truth['gt_bboxes_3d'], truth['gt_labels_3d'], classes)
            pred_boxes = instance_boxes(pred.bboxes_3d[keep], pred.labels_3d[keep].tolist(),
                                        classes, pred.scores_3d[keep].tolist())
            scan = load_scan(sample.lidar_path)
            name = Path(sample.lidar_path).stem
            draw_top_view(
                self.out_dir / f'{name}.png',
                scan,
                gt_boxes,
                pred_boxes,
                title=f'{name}: truth (solid), predictions >= {self.score_thr:g} (dashed)')
