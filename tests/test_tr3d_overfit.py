"""TR3D really learns: a few tiny generated rooms, converted with the real converter and trained
with the real Runner on configs/tr3d/tiny.py, are detected on themselves with mAP@0.25 >= 0.9
by mmdet3d's IndoorMetric (issue 5)."""
from pathlib import Path

from mmengine.config import Config
from mmengine.runner import Runner

from projects.synthdet.datasets.s3dis_converter import convert_s3dis
from tests.s3dis_fixtures import write_synthetic_area

REPO = Path(__file__).resolve().parents[1]


def test_tr3d_overfits_tiny_generated_rooms(tmp_path: Path) -> None:
    truth = write_synthetic_area(tmp_path / 'raw', area=1, n_rooms=3, seed=7,
                                 points_per_object=400)
    convert_s3dis(tmp_path / 'raw', tmp_path / 'data', areas=[1])
    data_root = f'{tmp_path / "data"}/'

    cfg = Config.fromfile(str(REPO / 'configs' / 'tr3d' / 'tiny.py'))
    cfg.train_dataloader.dataset.dataset.datasets[0].data_root = data_root
    cfg.val_dataloader.dataset.data_root = data_root
    cfg.test_dataloader.dataset.data_root = data_root
    cfg.train_cfg.val_interval = cfg.train_cfg.max_epochs + 1  # evaluate once, below
    cfg.default_hooks.checkpoint = None
    cfg.work_dir = str(tmp_path / 'work')
    runner = Runner.from_cfg(cfg)
    runner.train()
    metrics = runner.test()

    print({k: round(v, 3) for k, v in metrics.items() if 'AP' in k})
    classes = cfg.test_dataloader.dataset.metainfo['classes']
    assert sum(len(boxes) for boxes in truth.values()) >= 3 * len(classes)
    assert all(f'{name}_AP_0.25' in metrics for name in classes)
    assert metrics['mAP_0.25'] >= 0.9
