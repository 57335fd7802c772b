"""TR3D configs and tools through the real registries, Runner and command lines.

A module fixture writes two small generated rooms (tests/s3dis_fixtures.py), converts them with
the real converter and trains the tiny config for one epoch (2 iterations) with tools/train.py;
the tests then resume (tools/train.py --resume), test, predict and count with that checkpoint.
Training runs as a subprocess with one OpenMP thread; the test, predict and count tools' ``main``
run in this process with command-line arguments.
"""
import importlib.util
import json
import shutil
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
import torch
from mmengine.config import Config
from mmengine.registry import init_default_scope

from projects.synthdet.checkpoint import load_model_weights
from projects.synthdet.datasets.s3dis_converter import convert_s3dis
from projects.synthdet.evaluation.box_fit import best_fits, summarize_fits
from projects.synthdet.evaluation.table3 import format_table3, table3, table3_rows
from projects.synthdet.evaluation.table4 import truth_from_infos
from synthdet.contracts import ROOM_FORMAT, SchemaError
from synthdet.info_files import InfoFileError, load_info_pickle
from synthdet.scan_io import read_scan, write_scan
from tests.s3dis_fixtures import S3DIS_DIR, write_synthetic_area
from tests.tool_process import run_tool

REPO = Path(__file__).resolve().parents[2]
CONFIG_DIR = REPO / 'configs' / 'tr3d'
CONFIGS = sorted(CONFIG_DIR.glob('*.py'))
TINY = CONFIG_DIR / 'tiny.py'
TINY_CLASSES = ['table', 'chair', 'sofa', 'yumi', '3dprinter']
SYNTHETIC_CLASSES = ('table', 'chair', 'sofa', 'yumi', '3dprinter')
# (training areas, test area, classes) of the paper's experiments as this project defines them.
EXPERIMENTS = {
    'exp1': ([1, 2, 3, 4, 6], 5, ('table', 'chair', 'sofa', 'bookcase', 'board')),
    'exp2': ([7, 8], 9, SYNTHETIC_CLASSES),
    'exp3': ([1, 2, 3, 4, 6, 7, 8, 9], 5, SYNTHETIC_CLASSES),
    'exp3_finetune': ([1, 2, 3, 4, 6, 7, 8, 9], 5, SYNTHETIC_CLASSES),
    'exp2_paper': ([1, 2, 3, 7, 8], 9, SYNTHETIC_CLASSES),  # the paper's Table 2 lists these
    'exp2_cpu': ([7, 8], 9, SYNTHETIC_CLASSES),
}
# configs with TR3D's published S3DIS settings
FULL_SCALE = ('exp1', 'exp2', 'exp3', 'exp2_paper', 'exp3_finetune')


def load_tool(name: str) -> ModuleType:
    """Import tools/<name>.py (the tools folder is scripts, not a package)."""
    spec = importlib.util.spec_from_file_location(f'synthdet_tools_{name}',
                                                  REPO / 'tools' / f'{name}.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def data_options(data_root: Path) -> list[str]:
    """--cfg-options pointing the tiny config's datasets at a converted folder."""
    return [
        f'train_dataloader.dataset.dataset.datasets.0.data_root={data_root}/',
        f'val_dataloader.dataset.data_root={data_root}/',
        f'test_dataloader.dataset.data_root={data_root}/'
    ]


def best_checkpoint(tiny: dict) -> Path:
    """The tiny model's checkpoint of the best mAP@0.25."""
    return next(tiny['work'].glob('best_mAP_0.25_epoch_*.pth'))


def run_test_tool(tiny: dict, out_dir: Path, *options: str, data: Path | None = None) -> dict:
    """``tools/test.py`` in this process on the tiny model's best checkpoint and the tiny data
    (or ``data``) with ``options``; returns its table3 document."""
    return load_tool('test').main([
        str(TINY),
        str(best_checkpoint(tiny)), '--work-dir',
        str(out_dir), *options, '--cfg-options', *data_options(data or tiny['data'])
    ])


@pytest.fixture(scope='module')
def tiny(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """Two converted rooms and a work dir trained for one epoch by tools/train.py."""
    root = tmp_path_factory.mktemp('tr3d_tools')
    truth = write_synthetic_area(root / 'raw', area=1, n_rooms=2, seed=11, points_per_object=300)
    convert_s3dis(root / 'raw', root / 'data', areas=[1])
    work_dir = root / 'work'
    run_tool('tools/train.py', TINY, '--work-dir', work_dir, '--cfg-options',
             *data_options(root / 'data'), 'train_cfg.max_epochs=1', 'train_cfg.val_interval=1')
    return dict(
        root=root,
        data=root / 'data',
        work=work_dir,
        truth=truth,
        raw=root / 'raw' / S3DIS_DIR / 'Area_1')


@pytest.mark.parametrize('path', CONFIGS, ids=[p.stem for p in CONFIGS])
def test_registry_builds_the_model_of_every_config(path: Path) -> None:
    from mmdet3d.registry import MODELS
    from projects.synthdet.models import TR3DDetector

    cfg = Config.fromfile(str(path))
    init_default_scope(cfg.default_scope)
    model = MODELS.build(cfg.model)
    assert isinstance(model, TR3DDetector)
    assert model.bbox_head.num_classes == len(cfg.model.bbox_head.label2level)
    # The paper reports its best epoch; the CPU-scale configs test their final one (exp2_cpu's
    # area 9 validates and tests; the domain-shift models do not validate).
    final = ('exp2_cpu', 'domain_shift_cpu', 'domain_shift_mixed_cpu', 'teach_finetune',
             'adapt_selftrain')
    best_metric = None if path.stem in final else 'mAP_0.25'
    assert cfg.default_hooks.checkpoint.save_best == best_metric
    learning_rate = 0.0001 if path.stem == 'adapt_selftrain' else 0.001  # self-training: 1/10
    optimizer = dict(type='AdamW', lr=learning_rate, weight_decay=0.0001)
    if path.stem in ('exp2_cpu', 'teach_finetune', 'adapt_selftrain'):  # exp2_cpu's fused step
        optimizer['fused'] = True
    assert cfg.optim_wrapper.optimizer == optimizer
    assert cfg.optim_wrapper.clip_grad.max_norm == 10
    if 'test_dataloader' not in cfg:  # tr3d.py: the model base without data
        return
    classes = tuple(cfg.test_dataloader.dataset.metainfo['classes'])
    assert model.bbox_head.num_classes == len(classes)
    train_sets = cfg.train_dataloader.dataset.dataset.datasets
    assert all(tuple(d.metainfo['classes']) == classes for d in train_sets)
    assert all(d.type == 'SynthdetS3DISDataset'
               for d in [*train_sets, cfg.test_dataloader.dataset])
    validators = [] if path.stem.startswith('domain_shift') else [cfg.val_evaluator]
    assert all(e.type == 'SynthdetIndoorMetric' for e in [*validators, cfg.test_evaluator])
    if path.stem in EXPERIMENTS:
        train_areas, test_area, expected_classes = EXPERIMENTS[path.stem]
        assert [d.ann_file
                for d in train_sets] == [f's3dis_infos_Area_{a}.pkl' for a in train_areas]
        assert cfg.test_dataloader.dataset.ann_file == f's3dis_infos_Area_{test_area}.pkl'
        assert cfg.val_dataloader.dataset.ann_file == f's3dis_infos_Area_{test_area}.pkl'
        assert classes == expected_classes
    if path.stem in FULL_SCALE:
        assert cfg.model.voxel_size == model.bbox_head.voxel_size == 0.01
        assert cfg.train_dataloader.batch_size == 16 and cfg.train_dataloader.dataset.times == 13
        assert cfg.train_cfg.max_epochs == 5 and cfg.train_cfg.val_interval == 1
    if path.stem.startswith('exp2_cpu'):  # the CPU-scale differences, 1x schedule, one validation
        assert cfg.model.voxel_size == model.bbox_head.voxel_size == 0.02
        assert cfg.train_dataloader.batch_size == 4 and cfg.train_dataloader.dataset.times == 5
        assert cfg.param_scheduler.milestones == [8, 11] and cfg.param_scheduler.end == 12
        assert cfg.train_cfg.max_epochs == 12 and cfg.train_cfg.val_interval == 12
        assert model.neck.backbone_fine_level and model.neck.generated_reach == 1
        assert model.bbox_head.label2level == (2, 1, 1, 1, 0)
    points = {
        t.num_points
        for d in [*train_sets, cfg.test_dataloader.dataset]
        for t in d.pipeline if t.type == 'PointSample'
    }
    expected_points = {
        'exp2_cpu': 40000,
        'domain_shift_cpu': 40000,
        'domain_shift_mixed_cpu': 40000,
        'teach_finetune': 40000,
        'adapt_selftrain': 40000,
        'tiny': 10000
    }.get(path.stem, 100000)
    assert points == {expected_points}  # training and testing sample alike


def test_full_scale_experiments_share_one_architecture() -> None:
    from mmdet3d.registry import MODELS

    counts = {}
    for name in FULL_SCALE:
        cfg = Config.fromfile(str(CONFIG_DIR / f'{name}.py'))
        init_default_scope(cfg.default_scope)
        counts[name] = sum(p.numel() for p in MODELS.build(cfg.model).parameters())
    assert len(set(counts.values())) == 1, counts


def test_checkpoints_save_resume_and_load(tiny: dict) -> None:
    # Saved by tools/train.py: the newest epoch and the best validation mAP@0.25.
    first = tiny['work'] / 'epoch_1.pth'
    assert first.is_file() and (tiny['work'] / 'best_mAP_0.25_epoch_1.pth').is_file()
    saved = torch.load(first, map_location='cpu', weights_only=False)
    assert saved['meta']['epoch'] == 1 and saved['meta']['iter'] == 2
    assert list(saved['meta']['dataset_meta']['classes']) == TINY_CLASSES
    assert {int(s['step']) for s in saved['optimizer']['state'].values()} == {2}

    # Resume for one more epoch (2 iterations) into another work dir.
    resumed_dir = tiny['root'] / 'resumed'
    run_tool('tools/train.py', TINY, '--work-dir', resumed_dir, '--resume', first, '--cfg-options',
             *data_options(tiny['data']), 'train_cfg.max_epochs=2', 'val_cfg=None',
             'val_dataloader=None', 'val_evaluator=None')
    resumed = torch.load(resumed_dir / 'epoch_2.pth', map_location='cpu', weights_only=False)
    assert resumed['meta']['epoch'] == 2 and resumed['meta']['iter'] == 4
    # Adam continued from the saved state: 4 steps per parameter, not 2 of a fresh optimizer.
    assert {int(s['step']) for s in resumed['optimizer']['state'].values()} == {4}
    assert resumed['optimizer']['param_groups'][0]['lr'] == saved['optimizer']['param_groups'][0][
        'lr']
    # The weights continued too: BatchNorm counted 2 + 2 batches, and two Adam steps of
    # lr 1e-3 moved no parameter by more than a few lr (a fresh init differs by ~0.1).
    before, after = saved['state_dict'], resumed['state_dict']
    counters = [k for k in after if k.endswith('num_batches_tracked')]
    assert counters and all(int(before[k]) == 2 and int(after[k]) == 4 for k in counters)
    parameters = [
        k for k in after if not k.endswith(('running_mean', 'running_var', 'num_batches_tracked'))
    ]
    changes = [float((after[k] - before[k]).abs().max()) for k in parameters]
    assert 0 < max(changes) < 0.01

    # Load (weights-only, as the tools do): a freshly built model gets exactly the saved weights.
    from mmdet3d.registry import MODELS
    cfg = Config.fromfile(str(TINY))
    init_default_scope(cfg.default_scope)
    model = MODELS.build(cfg.model)
    load_model_weights(model, resumed_dir / 'epoch_2.pth')
    for key, value in model.state_dict().items():
        assert torch.equal(value, after[key]), key


def test_table3_layout_from_indoor_metric_results() -> None:
    metrics = {
        'table_AP_0.25': 0.96,
        'chair_AP_0.25': 0.72,
        'mAP_0.25': 0.84,
        'table_AP_0.50': 0.87,
        'chair_AP_0.50': 0.45,
        'mAP_0.50': 0.66
    }
    document = table3(metrics, ['table', 'chair', 'yumi'], 'c.py', 'c.pth', 'a.pkl')
    assert document['rows'] == {
        'mAP@0.25': {
            'table': 0.96,
            'chair': 0.72,
            'yumi': None,
            'mean': 0.84
        },
        'mAP@0.5': {
            'table': 0.87,
            'chair': 0.45,
            'yumi': None,
            'mean': 0.66
        }
    }
    text = format_table3(json.loads(json.dumps(document))).splitlines()
    assert text[0].split() == ['metric', 'table', 'chair', 'yumi', 'mean']
    assert text[1].split() == ['mAP@0.25', '0.960', '0.720', '-', '0.840']
    assert text[2].split() == ['mAP@0.5', '0.870', '0.450', '-', '0.660']
    with pytest.raises(KeyError, match='mAP_0.50'):
        table3_rows({'mAP_0.25': 0.5}, ['table'])


def test_test_tool_prints_and_writes_table3(tiny: dict, capsys: pytest.CaptureFixture) -> None:
    # In this process (the tool's own code, without a second start-up of the stack).
    out_dir = tiny['root'] / 'test_out'
    document = run_test_tool(tiny, out_dir)
    stdout = capsys.readouterr().out
    table = json.loads((out_dir / 'table3.json').read_text())
    assert table['format'] == 'synthdet.table3/1' and table['classes'] == TINY_CLASSES
    assert list(table['rows']) == ['mAP@0.25', 'mAP@0.5']
    for thr, row in zip(('0.25', '0.50'), table['rows'].values()):
        assert list(row) == [*TINY_CLASSES, 'mean']
        # every class is in the test rooms, so IndoorMetric reports an AP for each
        assert all(0.0 <= row[c] <= 1.0 for c in TINY_CLASSES)
        assert row['mean'] == pytest.approx(np.mean([row[c] for c in TINY_CLASSES]))
        assert row['mean'] == table['metrics'][f'mAP_{thr}']
    assert json.loads((out_dir / 'table3.json').read_text()) == document
    lines = stdout.splitlines()
    header = next(i for i, line in enumerate(lines) if line.split()[:1] == ['metric'])
    assert lines[header].split() == ['metric', *TINY_CLASSES, 'mean']
    assert lines[header + 1].split()[0] == 'mAP@0.25'
    assert float(lines[header + 1].split()[-1]) == pytest.approx(
        table['rows']['mAP@0.25']['mean'], abs=5e-4)
    assert lines[header + 2].split()[0] == 'mAP@0.5'


def test_test_tool_tta_tests_the_fused_passes(tiny: dict, tmp_path: Path) -> None:
    document = run_test_tool(tiny, tmp_path, '--tta')
    assert document == json.loads((tmp_path / 'table3.json').read_text())
    assert all(0.0 <= row[c] <= 1.0 for row in document['rows'].values() for c in TINY_CLASSES)
    without = tmp_path / 'without_tta.py'
    without.write_text(f"_base_ = ['{TINY}']\ntta_model = None\n")
    proc = subprocess.run([sys.executable, 'tools/test.py', without,
                           best_checkpoint(tiny), '--tta'],
                          cwd=REPO,
                          capture_output=True,
                          text=True,
                          timeout=300)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines()[-1] == (
        f'test.py: error: {without}: --tta needs tta_model and tta_pipeline in the config')


def test_best_fit_is_the_closest_prediction_of_the_same_class() -> None:
    from mmdet3d.structures import DepthInstance3DBoxes

    def boxes(rows: list[list[float]]) -> DepthInstance3DBoxes:  # gravity centre, size, yaw
        return DepthInstance3DBoxes(torch.tensor(rows).reshape(-1, 7), origin=(0.5, 0.5, 0.5))

    truth = boxes([[0, 0, 0.5, 1, 1, 1, 0], [5, 0, 0.5, 2, 1, 1, 0], [9, 9, 0.5, 1, 1, 1, 0]])
    pred = boxes([
        [0, 0, 0.5, 1, 1, 1, 0],  # exact on the first box, but of class 1
        [0.1, 0, 0.5, 1.25, 1, 1, 0],  # class 0, 1.25x as long: IoU 1 / 1.25
        [5, 0, 0.55, 1, 0.5, 0.9, 0],  # class 1, half as long and wide, 5 cm higher
        [5, 3, 0.5, 2, 1, 1, 0],  # class 1, a perfect size but 3 m off: IoU 0
    ])
    fits = best_fits(truth, [0, 1, 2], pred, [1, 0, 1, 1])
    assert fits[:, 0].tolist() == [0, 1, 2]
    np.testing.assert_allclose(fits[0, 1:], [0.8, 1.25, 1, 1, 0.1], rtol=1e-6, atol=1e-6)
    # second box: 2 x 1 x 1 against 1 x 0.5 x 0.9 inside it; 0.45 / 2 = 0.225
    np.testing.assert_allclose(fits[1, 1:], [0.225, 0.5, 0.5, 0.9, 0.05], rtol=1e-5, atol=1e-6)
    assert fits[2, 1] == 0 and np.isnan(fits[2, 2:]).all()  # class 2 has no prediction
    summary = summarize_fits(fits, ['table', 'chair', 'sofa', 'yumi'])
    assert summary['table_boxes'] == 1 and summary['table_below_0.25'] == 0.0
    assert summary['chair_below_0.25'] == summary['chair_below_0.50'] == 1.0
    assert summary['sofa_iou_median'] == 0 and np.isnan(summary['sofa_size_x'])
    assert not any(key.startswith('yumi') for key in summary)  # no true yumi
    assert best_fits(truth, [0, 1, 2], pred[[]], [])[:, 1].tolist() == [0, 0, 0]


def test_test_tool_box_fit_bounds_the_recall(tiny: dict, capsys: pytest.CaptureFixture) -> None:
    out_dir = tiny['root'] / 'test_box_fit'
    document = run_test_tool(tiny, out_dir, '--box-fit')
    fit = json.loads((out_dir / 'box_fit.json').read_text())
    assert fit['format'] == 'synthdet.box_fit/1' and list(fit['rows']) == TINY_CLASSES
    truth = [
        name for boxes in truth_from_infos([tiny['data'] / 's3dis_infos_Area_1.pkl']).values()
        for name, _ in boxes
    ]
    metrics = document['metrics']
    for name, row in fit['rows'].items():
        assert row['boxes'] == truth.count(name)
        assert 0.0 <= row['iou_median'] <= 1.0
        assert 0.0 <= row['below_0.25'] <= row['below_0.50'] <= 1.0
        # a true box IndoorMetric counts as found at IoU t has a prediction with IoU >= t
        for thr in ('0.25', '0.50'):
            assert 1.0 - row[f'below_{thr}'] >= metrics[f'{name}_rec_{thr}'] - 1e-9
    lines = capsys.readouterr().out.splitlines()
    header = next(i for i, line in enumerate(lines) if line.startswith('class '))
    assert lines[header].split()[:3] == ['class', 'boxes', 'iou_median']
    assert [line.split()[0] for line in lines[header + 1:header + 6]] == TINY_CLASSES
    assert (out_dir / 'box_fit.txt').read_text().count('\n') == 7  # title, header, 5 classes


def test_test_tool_names_what_the_false_positives_hit(tiny: dict, tmp_path: Path,
                                                      capsys: pytest.CaptureFixture) -> None:
    data = tmp_path / 'data'
    shutil.copytree(tiny['data'], data)
    shutil.copytree(tiny['raw'], data / S3DIS_DIR / 'Area_1')  # create_data's layout
    document = run_test_tool(tiny, tmp_path / 'out', '--false-positives', data=data)
    fps = json.loads((tmp_path / 'out' / 'false_positives.json').read_text())
    assert fps['format'] == 'synthdet.false_positives/1' and list(fps['rows']) == TINY_CLASSES
    annotated = {'floor', 'ceiling', 'wall', 'clutter', *TINY_CLASSES}
    for name, per_thr in fps['rows'].items():
        assert list(per_thr) == ['0.25', '0.50']
        for thr, entry in per_thr.items():
            assert entry['AP'] == pytest.approx(document['metrics'][f'{name}_AP_{thr}'], abs=1e-6)
            for cause, row in entry['causes'].items():
                assert row['count'] >= 1 and row['ap_without'] >= entry['AP'] - 1e-9
                assert cause.removeprefix('as ') in annotated or cause in ('duplicate', 'loose',
                                                                           'empty',
                                                                           'score < 0.1'), cause
    out = capsys.readouterr().out
    assert out.count('3dprinter  @0.') == 2
    assert (tmp_path / 'out' / 'false_positives.txt').read_text().count('\n') == 11


def test_predict_writes_detections_in_each_scan_frame(tiny: dict) -> None:
    room_txt = tiny['raw'] / 'office_1' / 'office_1.txt'
    converted_bin = tiny['data'] / 'points' / 'Area_1_office_1.bin'
    scans = tiny['root'] / 'scans'
    scans.mkdir()
    points = read_scan(room_txt)
    room_min, room_max = points[:, :3].min(axis=0), points[:, :3].max(axis=0)
    # The same points, in the same order, shifted near the origin (.bin) and as .ply. The shift
    # is whole metres: the preparation's outlier cells and voxels then fall alike in both frames.
    shift = np.floor(room_min)
    shifted_bin, room_ply = scans / 'office_1_shifted.bin', scans / 'office_1_copy.ply'
    write_scan(shifted_bin, np.column_stack([points[:, :3] - shift, points[:, 3:]]))
    write_scan(room_ply, points)
    out = tiny['root'] / 'pred'
    checkpoint = best_checkpoint(tiny)
    written = load_tool('predict').main(
        [str(p) for p in (TINY, checkpoint, room_txt, shifted_bin, room_ply, converted_bin)] +
        ['--out',
         str(out), '--score-thr', '0', '--cfg-options', 'model.test_cfg.score_thr=0.0'])
    assert len(written) == 4
    documents = {}
    for scan in (room_txt, shifted_bin, room_ply, converted_bin):
        document = json.loads((out / f'{scan.stem}.pred.json').read_text())
        assert document['format'] == 'synthdet.predictions/1' and document['scan'] == str(scan)
        assert document['model'] == 'tiny' and document['classes'] == TINY_CLASSES
        assert document['detections'], 'score_thr 0 keeps every box left after NMS'
        for det in document['detections']:
            assert set(det) == {'class', 'score', 'center', 'size', 'yaw'}
            assert det['class'] in TINY_CLASSES and 0.0 <= det['score'] <= 1.0
            assert len(det['center']) == 3 and len(det['size']) == 3
            assert all(s > 0 for s in det['size']) and det['yaw'] == 0.0
        scores = [det['score'] for det in document['detections']]
        assert scores == sorted(scores, reverse=True)
        documents[scan.stem] = document

    def centres(name: str) -> np.ndarray:
        return np.array([d['center'] for d in documents[name]['detections']])

    # Boxes of a barely trained model are rough: near the room, in the scan's frame.
    margin = 2.0
    for name in ('office_1', 'office_1_copy'):  # the raw room frame, metres from the origin
        assert np.all(centres(name) > room_min - margin)
        assert np.all(centres(name) < room_max + margin)
    for name, origin in (('office_1_shifted', shift), ('Area_1_office_1', room_min)):
        assert np.all(centres(name) > -margin)  # the shifted frames
        assert np.all(centres(name) < room_max - origin + margin)
    # Same points in another frame: the same detections, moved by the frame difference.
    raw, shifted = documents['office_1']['detections'], documents['office_1_shifted']['detections']
    assert [d['class'] for d in raw] == [d['class'] for d in shifted]
    np.testing.assert_allclose([d['score'] for d in raw], [d['score'] for d in shifted], atol=1e-5)
    np.testing.assert_allclose(centres('office_1') - shift, centres('office_1_shifted'), atol=1e-4)


def test_predict_tta_boxes_come_back_into_each_scan_frame(tiny: dict, tmp_path: Path) -> None:
    room_txt = tiny['raw'] / 'office_1' / 'office_1.txt'
    points = read_scan(room_txt)
    room_min, room_max = points[:, :3].min(axis=0), points[:, :3].max(axis=0)
    shift = np.floor(room_min)
    shifted_bin = tmp_path / 'office_1_shifted.bin'
    write_scan(shifted_bin, np.column_stack([points[:, :3] - shift, points[:, 3:]]))
    checkpoint = best_checkpoint(tiny)
    load_tool('predict').main([
        str(TINY), str(checkpoint), str(room_txt), str(shifted_bin), '--out', str(tmp_path),
        '--tta', '--score-thr', '0', '--cfg-options', 'model.test_cfg.score_thr=0.0'
    ])
    raw, shifted = (json.loads((tmp_path / f'{name}.pred.json').read_text())['detections']
                    for name in ('office_1', 'office_1_shifted'))
    assert raw and [d['class'] for d in raw] == [d['class'] for d in shifted]
    centres = np.array([d['center'] for d in raw])
    # a box left flipped would lie mirrored about the room's corner, metres outside it
    assert np.all(centres > room_min - 2.0) and np.all(centres < room_max + 2.0)
    np.testing.assert_allclose(centres - shift, [d['center'] for d in shifted], atol=1e-4)
    np.testing.assert_allclose([d['score'] for d in raw], [d['score'] for d in shifted], atol=1e-5)


def test_count_table_counts_correct_and_incorrect_detections(tmp_path: Path) -> None:
    count_table = load_tool('count_table')
    room = tmp_path / 'Area_9' / 'lab_1'
    room.mkdir(parents=True)
    (room / 'lab_1.txt').write_text('0 0 0 0 0 0\n')
    objects = [
        ('chair_1', 'chair', [1.0, 1.0, 0.45], [0.5, 0.5, 0.9], 0.0),
        ('chair_2', 'chair', [3.0, 1.0, 0.45], [0.5, 0.5, 0.9], 0.0),
        # rotated by 90 degrees: its axis-aligned box is 0.7 x 1.2
        ('table_1', 'table', [2.0, 3.0, 0.375], [1.2, 0.7, 0.75], np.pi / 2),
    ]
    (room / 'meta.json').write_text(
        json.dumps({
            'format':
            'synthdet.room/1',
            'seed':
            0,
            'generator': {},
            'room': {
                'polygon': [[0, 0], [0, 5], [5, 5], [5, 0]],
                'height': 3.0
            },
            'objects': [{
                'instance': i,
                'class': c,
                'asset': f'{c}/x',
                'params': {},
                'box': {
                    'center': ctr,
                    'size': size,
                    'yaw': yaw
                },
                'on': None
            } for i, c, ctr, size, yaw in objects]
        }))

    def det(cls, score, center, size):
        return {'class': cls, 'score': score, 'center': center, 'size': size, 'yaw': 0.0}

    predictions = {
        'sd': (
            ['table', 'chair', 'sofa', 'yumi', '3dprinter'],
            [
                det('chair', 0.9, [1.02, 1.0, 0.45], [0.5, 0.5, 0.9]),  # correct
                det('chair', 0.8, [1.0, 1.02, 0.45], [0.5, 0.5, 0.9]),  # duplicate: incorrect
                det('chair', 0.2, [3.0, 1.0, 0.45], [0.5, 0.5, 0.9]),  # below 0.3: ignored
                det('table', 0.7, [2.0, 3.0, 0.375], [0.7, 1.2, 0.75]),  # correct (enclosing box)
                det('yumi', 0.5, [4.0, 4.0, 0.5], [0.5, 0.5, 1.0]),  # no yumi: incorrect
            ]),
        'baseline': (
            ['table', 'chair', 'sofa', 'bookcase', 'board'],
            [
                det('table', 0.9, [2.0, 3.0, 0.375], [1.2, 0.7, 0.75]),  # IoU 0.41: correct
                det('chair', 0.9, [3.25, 1.0, 0.45], [0.5, 0.5, 0.9]),  # IoU 0.33: correct
                det('chair', 0.9, [1.4, 1.0, 0.45], [0.5, 0.5, 0.9]),  # IoU 0.11: incorrect
            ]),
    }
    for model, (classes, detections) in predictions.items():
        (tmp_path / model).mkdir()
        (tmp_path / model / 'lab_1.pred.json').write_text(
            json.dumps({
                'format': 'synthdet.predictions/1',
                'scan': 'Area_9/lab_1/lab_1.txt',
                'model': model,
                'classes': classes,
                'detections': detections
            }))
    out = tmp_path / 'table4.json'
    table = count_table.main([
        str(tmp_path / 'sd'),
        str(tmp_path / 'baseline'), '--scan-root',
        str(tmp_path), '--out',
        str(out)
    ])
    assert json.loads(out.read_text()) == table
    assert table['format'] == 'synthdet.table4/1'
    assert table['classes'] == ['table', 'chair', 'sofa', 'bookcase', 'board', 'yumi', '3dprinter']
    (row, ) = table['scans']
    assert row['truth'] == {
        'table': 1,
        'chair': 2,
        'sofa': 0,
        'bookcase': 0,
        'board': 0,
        'yumi': 0,
        '3dprinter': 0
    }
    sd, baseline = row['models']['sd'], row['models']['baseline']
    assert sd['chair'] == {'correct': 1, 'incorrect': 1}
    assert sd['table'] == {'correct': 1, 'incorrect': 0}
    assert sd['yumi'] == {'correct': 0, 'incorrect': 1}
    assert sd['bookcase'] is None and baseline['yumi'] is None
    assert baseline['table'] == {'correct': 1, 'incorrect': 0}
    assert baseline['chair'] == {'correct': 1, 'incorrect': 1}

    bad = tmp_path / 'bad.pred.json'
    bad.write_text(json.dumps({'format': 'synthdet.predictions/0'}))
    with pytest.raises(SchemaError, match='bad.pred.json'):
        count_table.main([str(bad)])


def test_count_table_reads_ground_truth_from_info_pickles(tiny: dict, tmp_path: Path) -> None:
    count_table = load_tool('count_table')
    info_file = tiny['data'] / 's3dis_infos_Area_1.pkl'
    truth = truth_from_infos([str(info_file)])
    assert set(truth) == {'Area_1_office_1.bin', 'Area_1_lab_1.bin'}
    # The converted boxes are the fixture's true boxes, shifted by the room minimum.
    boxes = truth['Area_1_office_1.bin']
    expected = tiny['truth']['office_1']
    assert sorted(c for c, _ in boxes) == sorted(b['class'] for b in expected)
    detections = [{
        'class': c,
        'score': 0.9,
        'center': b[:3],
        'size': b[3:],
        'yaw': 0.0
    } for c, b in boxes]
    (tmp_path / 'Area_1_office_1.pred.json').write_text(
        json.dumps({
            'format': 'synthdet.predictions/1',
            'scan': 'data/s3dis/points/Area_1_office_1.bin',
            'model': 'tiny',
            'classes': TINY_CLASSES,
            'detections': detections
        }))
    table = count_table.main([str(tmp_path), '--infos', str(info_file)])
    cells = table['scans'][0]['models']['tiny']
    for cls in TINY_CLASSES:
        n = sum(c == cls for c, _ in boxes)
        assert table['scans'][0]['truth'][cls] == n
        assert cells[cls] == {'correct': n, 'incorrect': 0}


def _write_meta(room_dir: Path, sensor: str | None) -> None:
    """A minimal generator ``meta.json`` recording ``sensor`` (none: from before the sensors)."""
    generator = {} if sensor is None else {'sensor': {'model': sensor}}
    room = {'polygon': [[0.0, 0.0], [0.0, 4.0], [4.0, 4.0], [4.0, 0.0]], 'height': 3.0}
    document = {'format': ROOM_FORMAT, 'room': room, 'objects': [], 'generator': generator}
    (room_dir / 'meta.json').write_text(json.dumps(document))


def test_test_tool_tests_the_rooms_of_one_sensor(tiny: dict, tmp_path: Path) -> None:
    data = tmp_path / 'data'
    shutil.copytree(tiny['data'], data)
    shutil.copytree(tiny['raw'], data / S3DIS_DIR / 'Area_1')
    rooms = [
        Path(info['lidar_points']['lidar_path']).stem.removeprefix('Area_1_')
        for info in load_info_pickle(data / 's3dis_infos_Area_1.pkl')['data_list']
    ]
    assert len(rooms) == 2
    checkpoint = best_checkpoint(tiny)
    test = load_tool('test')

    def run(name: str, sensor: str | None = None, *options: str) -> dict:
        return test.main([
            str(TINY),
            str(checkpoint), '--work-dir',
            str(tmp_path / name), *(['--sensor', sensor] if sensor else []), '--cfg-options',
            *data_options(data), *options
        ])

    _write_meta(data / S3DIS_DIR / 'Area_1' / rooms[0], 'tls')
    with pytest.raises(InfoFileError, match=f'{rooms[1]}.*no generator meta.json'):
        run('missing', 'tls')
    _write_meta(data / S3DIS_DIR / 'Area_1' / rooms[1], None)  # counts as the paper sensor
    for sensor, index in (('tls', 0), ('paper', 1)):
        by_sensor = run(sensor, sensor)
        by_index = run(f'index_{index}', None, f'test_dataloader.dataset.indices=[{index}]')
        assert by_sensor['test_set'] == f's3dis_infos_Area_1.pkl ({sensor} rooms)'
        assert by_sensor['rows'] == by_index['rows'] and by_sensor['metrics'] == by_index['metrics']
    with pytest.raises(InfoFileError, match='no room scanned by the tablet sensor'):
        run('tablet', 'tablet')
