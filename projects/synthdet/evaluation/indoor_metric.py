"""mmdet3d's IndoorMetric with the paper's rule for classes the test set does not contain.

mmdet3d's ``indoor_eval`` gives a class that is predicted but has no ground truth an AP of NaN
(recall 0/0), and the NaN spreads to the mean: experiment 3 predicts yumi and 3dprinter on
S3DIS area 5, which has none, so its mAP would be NaN and the checkpoint hook's
``save_best='mAP_0.25'`` would never keep an epoch (``nan > best`` is false). The paper shows
such classes as "-" in Table 3 and leaves them out of the mean; :class:`SynthdetIndoorMetric`
does the same (``table3.without_classes``), so the Table 3 document has ``null`` for them.
"""
from mmdet3d.evaluation.metrics import IndoorMetric
from mmdet3d.registry import METRICS
from mmengine.logging import MMLogger

from .table3 import without_classes


@METRICS.register_module()
class SynthdetIndoorMetric(IndoorMetric):
    """``IndoorMetric`` whose results leave out the classes without a ground-truth box in the
    evaluated samples: no ``<class>_AP_<thr>`` / ``<class>_rec_<thr>`` entries, and ``mAP`` and
    ``mAR`` are the means over the other classes. Same arguments as ``IndoorMetric``."""

    def compute_metrics(self, results: list) -> dict[str, float]:
        classes = self.dataset_meta['classes']
        with_truth = {int(label) for eval_ann, _ in results for label in eval_ann['gt_labels_3d']}
        absent = [name for label, name in enumerate(classes) if label not in with_truth]
        if absent:
            MMLogger.get_current_instance().info(
                f'classes without ground truth, left out of Table 3 and the means (the NaN '
                f'rows of the table above): {", ".join(absent)}')
        return without_classes(super().compute_metrics(results), absent, self.iou_thr)
