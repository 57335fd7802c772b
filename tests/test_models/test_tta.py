"""Test-time augmentation (projects/synthdet/models/tta.py) through mmcv's real TestTimeAug, the
real flips and mmengine's BaseTTAModel.test_step, around a detector that boxes all its points:
every flipped pass must come back into the scene's frame and fuse into one box."""
import numpy as np
import torch
from mmdet3d.structures import DepthInstance3DBoxes
from mmdet3d.utils import register_all_modules
from mmengine.dataset import Compose, pseudo_collate
from mmengine.structures import InstanceData
from torch import nn

from projects.synthdet.config_helpers import with_test_time_augmentation
from projects.synthdet.models import SynthdetTTAModel


class BoundingBoxDetector(nn.Module):
    """Predicts one box of class 1 around all the points of a scene, with score 1."""

    def __init__(self) -> None:
        super().__init__()
        self.flips = []

    def test_step(self, data: dict) -> list:
        samples = []
        for points, sample in zip(data['inputs']['points'], data['data_samples']):
            xyz = points[:, :3]
            low, high = xyz.min(dim=0).values, xyz.max(dim=0).values
            pred = InstanceData()
            pred.bboxes_3d = DepthInstance3DBoxes(
                torch.cat(((low + high) / 2, high - low))[None],
                box_dim=6,
                with_yaw=False,
                origin=(0.5, 0.5, 0.5))
            pred.scores_3d = torch.ones(1)
            pred.labels_3d = torch.ones(1, dtype=torch.long)
            sample.pred_instances_3d = pred
            self.flips.append((sample.pcd_horizontal_flip, sample.pcd_vertical_flip))
            samples.append(sample)
        return samples


def test_flipped_passes_fuse_back_into_the_scene_frame(tmp_path):
    register_all_modules()
    rng = np.random.default_rng(0)
    # an object off the origin, so that every flip moves it elsewhere
    xyz = rng.uniform((2.0, 0.5, 0.0), (2.8, 1.5, 0.6), size=(500, 3))
    points = np.hstack((xyz, rng.uniform(0, 255, size=(500, 3)))).astype(np.float32)
    path = tmp_path / 'scene.bin'
    points.tofile(path)
    test_pipeline = [
        dict(
            type='LoadPointsFromFile', coord_type='DEPTH', load_dim=6, use_dim=[0, 1, 2, 3, 4, 5]),
        dict(type='PointSample', num_points=500),  # all points, shuffled
        dict(type='Pack3DDetInputs', keys=['points'])
    ]
    versions = Compose(with_test_time_augmentation(test_pipeline, draws=2))(
        dict(
            lidar_points=dict(lidar_path=str(path)),
            box_type_3d=DepthInstance3DBoxes,
            box_mode_3d=None))
    detector = BoundingBoxDetector()
    model = SynthdetTTAModel(module=detector, fusion_iou_thr=0.5)
    (merged, ) = model.test_step(pseudo_collate([versions]))

    assert sorted(detector.flips) == sorted([(h, v) for h in (False, True)
                                             for v in (False, True)] * 2)
    pred = merged.pred_instances_3d
    assert pred.labels_3d.tolist() == [1] and pred.scores_3d.tolist() == [1.0]
    expected = np.concatenate(((xyz.min(0) + xyz.max(0)) / 2, xyz.max(0) - xyz.min(0)))
    np.testing.assert_allclose(
        torch.cat((pred.bboxes_3d.gravity_center, pred.bboxes_3d.dims), dim=1)[0].numpy(),
        expected,
        atol=1e-5)
