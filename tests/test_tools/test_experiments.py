"""Experiments 1 and 3 as a user runs them, at the smallest scale.

A module fixture writes a training area of four rooms with all five classes of experiments 2
and 3 and a test area of two rooms without yumi and 3dprinter (as S3DIS area 5 in experiment
3), converts them and trains the tiny config with ``tools/dist_train.sh``: two CPU processes
(gloo), two iterations each, validation on the test area after the epoch. The tests then check
what the processes saw and learned, the best-epoch checkpoint, Table 3 with "-" for the two
absent classes, ``tools/test.py --show-dir`` and ``tools/dist_test.sh`` against the
single-process test. The training config is ``tiny.py`` plus a recording hook
(``tests/rank_record_hook.py``); its test pipeline keeps every point (no random sampling), so
that one process and two see the same inputs.
"""
import json
import math
import os
import pickle
import socket
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from mmengine.config import Config

from projects.synthdet.datasets.s3dis_converter import convert_s3dis
from projects.synthdet.evaluation.table3 import without_classes
from tests.s3dis_fixtures import write_synthetic_area
from tests.test_tools.test_tr3d_tools import data_options, load_tool

REPO = Path(__file__).resolve().parents[2]
TINY = REPO / 'configs' / 'tr3d' / 'tiny.py'
ABSENT = ('yumi', '3dprinter')
PRESENT = ('table', 'chair', 'sofa')

EXPERIMENT_CONFIG = f"""_base_ = ['{TINY}']
custom_imports = dict(
    imports=[
        'projects.synthdet.datasets.synthdet_s3dis', 'projects.synthdet.models',
        'projects.synthdet.evaluation.indoor_metric', 'tests.rank_record_hook'
    ],
    allow_failed_imports=False)
custom_hooks = [dict(type='RankRecordHook', out_dir='{{record_dir}}')]
train_cfg = dict(max_epochs=1, val_interval=1)
test_pipeline = [step for step in _base_.test_pipeline if step['type'] != 'PointSample']
val_dataloader = dict(dataset=dict(ann_file='s3dis_infos_Area_2.pkl', pipeline=test_pipeline))
test_dataloader = val_dataloader
# the project's metric and, to see what mmdet3d's own would say, IndoorMetric
test_evaluator = [dict(type='SynthdetIndoorMetric'), dict(type='IndoorMetric', prefix='mmdet3d')]
"""


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(('127.0.0.1', 0))
        return sock.getsockname()[1]


def run_tool(tool: str, *args: str | Path | int) -> subprocess.CompletedProcess:
    """Run tools/<tool> (a Python tool, or a shell script with this interpreter as ``PYTHON``
    and a free port) with one OpenMP thread; fail with its output if it exits non-zero."""
    env = {
        **os.environ, 'OMP_NUM_THREADS': os.environ.get('OMP_NUM_THREADS', '1'),
        'PYTHON': sys.executable,
        'PORT': str(free_port())
    }
    program = ['bash'] if tool.endswith('.sh') else [sys.executable]
    proc = subprocess.run([*program, f'tools/{tool}', *map(str, args)],
                          cwd=REPO,
                          capture_output=True,
                          text=True,
                          timeout=900,
                          env=env)
    assert proc.returncode == 0, f'{tool} failed:\n{proc.stdout[-3000:]}\n{proc.stderr[-6000:]}'
    return proc


@pytest.fixture(scope='module')
def experiment(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """Areas 1 (training) and 2 (test, no yumi or 3dprinter), converted, and a work dir trained
    by tools/dist_train.sh with 2 processes and --auto-scale-lr."""
    root = tmp_path_factory.mktemp('experiments')
    write_synthetic_area(root / 'raw', area=1, n_rooms=4, seed=3, points_per_object=150)
    write_synthetic_area(
        root / 'raw', area=2, n_rooms=2, seed=4, points_per_object=150, classes=PRESENT)
    convert_s3dis(root / 'raw', root / 'data')
    config = root / 'tiny_experiment.py'
    config.write_text(EXPERIMENT_CONFIG.format(record_dir=root / 'record'))
    work = root / 'work'
    run_tool('dist_train.sh', config, 2, '--work-dir', work, '--auto-scale-lr', '--cfg-options',
             *data_options(root / 'data'))
    return dict(root=root, config=config, data=root / 'data', work=work)


@pytest.mark.slow
def test_two_processes_train_on_different_rooms_and_end_with_equal_weights(
        experiment: dict) -> None:
    ranks = [torch.load(experiment['root'] / 'record' / f'rank{r}.pth') for r in (0, 1)]
    assert [r['world_size'] for r in ranks] == [2, 2]
    seen = [r['seen'] for r in ranks]
    assert [len(s) for s in seen] == [2, 2]  # 2 iterations of batch 1 each
    assert set(seen[0]).isdisjoint(seen[1])
    with open(experiment['data'] / 's3dis_infos_Area_1.pkl', 'rb') as f:
        rooms = {info['lidar_points']['lidar_path'] for info in pickle.load(f)['data_list']}
    assert set(seen[0]) | set(seen[1]) == rooms
    first, second = ranks
    assert first['final'].keys() == second['final'].keys() == first['initial'].keys()
    for name in first['final']:
        assert torch.equal(first['initial'][name], second['initial'][name]), name
        assert torch.equal(first['final'][name], second['final'][name]), name
    changed = [
        n for n in first['final'] if not torch.equal(first['initial'][n], first['final'][n])
    ]
    assert len(changed) == len(first['final'])  # every parameter was trained


@pytest.mark.slow
def test_auto_scale_lr_counts_both_processes(experiment: dict) -> None:
    scalars = next(experiment['work'].glob('*/vis_data/scalars.json')).read_text().splitlines()
    lrs = [json.loads(line)['lr'] for line in scalars if 'lr' in json.loads(line)]
    assert lrs and lrs == pytest.approx([1e-3 * 2 * 1 / 16] * len(lrs))  # x 2 processes / 16


@pytest.mark.slow
def test_best_epoch_is_kept_although_the_test_area_lacks_two_classes(experiment: dict) -> None:
    scalars = next(experiment['work'].glob('*/vis_data/scalars.json')).read_text().splitlines()
    val = [json.loads(line) for line in scalars if 'mAP_0.25' in json.loads(line)]
    assert len(val) == 1 and math.isfinite(val[0]['mAP_0.25'])
    assert not any(f'{name}_AP_0.25' in val[0] for name in ABSENT)
    assert (experiment['work'] / 'best_mAP_0.25_epoch_1.pth').is_file()


@pytest.fixture(scope='module')
def single_test(experiment: dict) -> dict:
    """tools/test.py in one process on the best checkpoint, with pictures of every scan."""
    out = experiment['root'] / 'test_single'
    proc = run_tool('test.py', experiment['config'],
                    experiment['work'] / 'best_mAP_0.25_epoch_1.pth', '--work-dir', out,
                    '--show-dir', out / 'show', '--score-thr', '0.05', '--cfg-options',
                    *data_options(experiment['data']))
    return dict(out=out, stdout=proc.stdout, table=json.loads((out / 'table3.json').read_text()))


@pytest.mark.slow
def test_table3_shows_a_dash_for_classes_without_truth(single_test: dict) -> None:
    table = single_test['table']
    metrics = table['metrics']
    # the model predicted both absent classes: mmdet3d's IndoorMetric gives them NaN, and its mean
    for name in ABSENT:
        assert math.isnan(metrics[f'mmdet3d/{name}_AP_0.25'])
    assert math.isnan(metrics['mmdet3d/mAP_0.25'])
    for row, thr in zip(table['rows'].values(), ('0.25', '0.50')):
        assert [row[name] for name in ABSENT] == [None, None]
        present = [row[name] for name in PRESENT]
        assert all(0.0 <= ap <= 1.0 for ap in present)
        assert row['mean'] == pytest.approx(sum(present) / 3) == metrics[f'mAP_{thr}']
        assert present == [metrics[f'mmdet3d/{name}_AP_{thr}'] for name in PRESENT]
    header = next(line for line in single_test['stdout'].splitlines() if line.startswith('metric'))
    row = single_test['stdout'].splitlines()[single_test['stdout'].splitlines().index(header) + 1]
    assert header.split() == ['metric', *PRESENT, *ABSENT, 'mean']
    assert row.split()[4:6] == ['-', '-']
    assert (single_test['out'] / 'table3.txt').read_text().count(' - ') >= 2


@pytest.mark.slow
def test_show_dir_draws_one_picture_per_scan(single_test: dict) -> None:
    pictures = sorted(p.name for p in (single_test['out'] / 'show').glob('*.png'))
    assert pictures == ['Area_2_lab_1.png', 'Area_2_office_1.png']
    for picture in pictures:
        assert (single_test['out'] / 'show' / picture).stat().st_size > 10_000


@pytest.mark.slow
def test_dist_test_gives_the_metrics_of_the_single_process_test(experiment: dict,
                                                                single_test: dict) -> None:
    out = experiment['root'] / 'test_dist'
    run_tool('dist_test.sh', experiment['config'],
             experiment['work'] / 'best_mAP_0.25_epoch_1.pth', 2, '--work-dir', out,
             '--cfg-options', *data_options(experiment['data']))
    table = json.loads((out / 'table3.json').read_text())
    # json.dumps compares NaN (mmdet3d's own metric) as equal text
    assert json.dumps(table['metrics']) == json.dumps(single_test['table']['metrics'])
    assert table['rows'] == single_test['table']['rows']


def test_without_classes_recomputes_the_means() -> None:
    nan = float('nan')
    metrics = {
        'table_AP_0.25': 0.5,
        'chair_AP_0.25': 1.0,
        'yumi_AP_0.25': nan,
        'mAP_0.25': nan,
        'table_rec_0.25': 1.0,
        'chair_rec_0.25': 0.5,
        'yumi_rec_0.25': nan,
        'mAR_0.25': nan
    }
    assert without_classes(metrics, ['yumi'], [0.25]) == {
        'table_AP_0.25': 0.5,
        'chair_AP_0.25': 1.0,
        'mAP_0.25': 0.75,
        'table_rec_0.25': 1.0,
        'chair_rec_0.25': 0.5,
        'mAR_0.25': 0.75
    }
    assert math.isnan(without_classes(metrics, ['table', 'chair', 'yumi'], [0.25])['mAP_0.25'])


def test_train_options_amp_and_auto_scale_lr(tmp_path: Path) -> None:
    train = load_tool('train')
    args = train.parse_args([str(TINY), '--amp', '--auto-scale-lr'])
    cfg = train.build_config(args)
    assert cfg.optim_wrapper.type == 'AmpOptimWrapper'
    assert cfg.optim_wrapper.loss_scale == 'dynamic'
    assert cfg.auto_scale_lr == dict(enable=True, base_batch_size=16)
    assert Config.fromfile(str(TINY)).auto_scale_lr.enable is False
    bare = tmp_path / 'bare.py'
    bare.write_text(f"_base_ = ['{TINY}']\nauto_scale_lr = dict(_delete_=True, enable=False)\n")
    with pytest.raises(ValueError, match='base_batch_size'):
        train.build_config(train.parse_args([str(bare), '--auto-scale-lr']))
    if not torch.cuda.is_available():
        proc = subprocess.run([sys.executable, 'tools/train.py',
                               str(TINY), '--amp'],
                              cwd=REPO,
                              capture_output=True,
                              text=True,
                              timeout=300)
        assert proc.returncode == 2  # a usage error (docs/safety.md)
        assert proc.stderr.strip().splitlines()[-1] == (
            "train: error: --amp needs a CUDA GPU (mmengine's AmpOptimWrapper); none found")
