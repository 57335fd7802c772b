"""TR3D really learns: three tiny generated rooms, converted with the real converter, trained with
tools/train.py (the Runner) on configs/tr3d/tiny.py and tested on themselves with tools/test.py,
reach mAP@0.25 >= 0.9 with mmdet3d's IndoorMetric."""
import json
from pathlib import Path

from projects.synthdet.datasets.s3dis_converter import convert_s3dis
from tests.s3dis_fixtures import write_synthetic_area
from tests.tool_process import run_tool

REPO = Path(__file__).resolve().parents[2]
TINY = REPO / 'configs' / 'tr3d' / 'tiny.py'


def test_tr3d_overfits_tiny_generated_rooms(tmp_path: Path) -> None:
    truth = write_synthetic_area(
        tmp_path / 'raw', area=1, n_rooms=3, seed=7, points_per_object=300)
    convert_s3dis(tmp_path / 'raw', tmp_path / 'data', areas=[1])
    data = [
        f'train_dataloader.dataset.dataset.datasets.0.data_root={tmp_path / "data"}/',
        f'val_dataloader.dataset.data_root={tmp_path / "data"}/',
        f'test_dataloader.dataset.data_root={tmp_path / "data"}/'
    ]
    work = tmp_path / 'work'
    # Train without validation (tools/test.py evaluates the final weights below).
    run_tool('tools/train.py', TINY, '--work-dir', work, '--cfg-options', *data, 'val_cfg=None',
             'val_dataloader=None', 'val_evaluator=None')
    proc = run_tool('tools/test.py', TINY, work / 'epoch_24.pth', '--work-dir', work,
                    '--cfg-options', *data)
    print(proc.stdout[proc.stdout.index('Table 3'):])

    table = json.loads((work / 'table3.json').read_text())
    classes = table['classes']
    assert classes == ['table', 'chair', 'sofa', 'yumi', '3dprinter']
    assert sum(len(boxes) for boxes in truth.values()) >= len(classes) * 3
    assert all(table['rows']['mAP@0.25'][name] is not None for name in classes)
    assert table['metrics']['mAP_0.25'] == table['rows']['mAP@0.25']['mean'] >= 0.9
