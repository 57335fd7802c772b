"""The measured fine-tune on corrected rooms (benchmarks/bench_teach.py): how it plans a
correction (overlapping true boxes kept as they are), and one whole run at a tiny scale through the
real scan2cad, FreeCAD, labels, converter, Runner and evaluation (one training iteration; the
benchmark's ``main`` in this process, its tools forked from one process that imported the stack:
``--fork-tools``)."""
from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Callable

import numpy as np
import pytest

from benchmarks.bench_real_scans import write_generated_scans
from benchmarks.bench_teach import correction_plan, main
from benchmarks.tool_runs import run_tool
from synthdet.contracts import LABELS_FORMAT, read_labels, write_labels
from synthdet.scan_io import write_scan
from tests.checkpoints import initial_checkpoint
from tests.room_scans import make_room
from tests.s3dis_fixtures import write_synthetic_area

REPO = Path(__file__).resolve().parents[2]
CLASSES = ['table', 'chair', 'sofa', 'yumi', '3dprinter']
NUMBER = r'(\d+\.\d+)'
HEADLINE = re.compile(rf'teach: held-out recall {NUMBER} -> {NUMBER} at IoU 0\.25, false '
                      rf'positives per room {NUMBER} -> {NUMBER}, area 9 mAP@0\.25 {NUMBER} -> '
                      rf'{NUMBER} \(2 training rooms, 1 held-out rooms, fine-tune {NUMBER} min\)')


def box(name: str, center, size, yaw: float = 0.0, label: str = '') -> dict:
    return {
        'class': name,
        'center': list(center),
        'size': list(size),
        'yaw': yaw,
        'label': label or name
    }


def test_the_correction_keeps_matched_parts_deletes_the_rest_and_adds_the_missed():
    truth = [
        box('chair', (1.0, 1.0, 0.45), (0.5, 0.5, 0.9)),
        box('table', (3.0, 1.0, 0.375), (1.4, 0.8, 0.75)),
        box('chair', (3.5, 1.4, 0.45), (0.5, 0.5, 0.9))  # pushed half under the table
    ]
    parts = [
        dict(box('chair', (1.1, 1.0, 0.45), (0.5, 0.5, 0.9)), name='Chair001'),
        dict(box('sofa', (3.0, 1.0, 0.4), (1.8, 0.9, 0.8)), name='Sofa001'),  # wrong class
        dict(box('chair', (8.0, 1.0, 0.45), (0.5, 0.5, 0.9)), name='Chair002'),  # phantom
        dict(box('chair', (1.0, 1.1, 0.45), (0.5, 0.5, 0.9)), name='Chair003')
    ]  # second
    plan = correction_plan(parts, truth)
    assert [(item['name'], item['box']['center'])
            for item in plan['edit']] == [('Chair001', [1.0, 1.0, 0.45])]
    assert plan['add'] == [{key: item[key] for key in ('class', 'center', 'size', 'yaw')}
                           for item in truth[1:]]  # the overlapping boxes as labelled
    assert all(set(item) == {'class', 'center', 'size', 'yaw'} for item in plan['add'])


# teach_finetune.py with the user's area once in the training set instead of `user_repeat`
# times: every repeat is a dataset the Runner builds (a few tenths of a CPU second each)
ONE_REPEAT_FINETUNE = """_base_ = ['{base}']
from projects.synthdet.config_helpers import area_datasets  # noqa: E402

train_dataloader = dict(
    dataset=dict(
        dataset=dict(
            datasets=area_datasets(
                dict(_base_.train_area_dataset, pipeline=_base_.train_pipeline),
                [*_base_.train_area, _base_.user_area], _base_.metainfo))))
"""


def generated_areas(root: Path) -> Path:
    """One small generated room in each of the areas 7, 8 and 9, converted under ``root``; the
    data root."""
    generated, data = root / 'generated', root / 'data'
    for area in (7, 8, 9):
        write_synthetic_area(generated, area, n_rooms=1, seed=area, points_per_object=300)
    converted = run_tool(['tools/create_data.py', 's3dis', '--root-path', generated, '--out-dir',
                          data], forked=True)
    assert converted.returncode == 0, converted.stderr[-3000:]
    return data


def run_from_repo(main: Callable[[list[str]], int], command: list, monkeypatch, capsys) -> str:
    """A benchmark's ``main`` run from the repository root on one thread: what it printed
    (it must exit 0)."""
    monkeypatch.setenv('OMP_NUM_THREADS', '1')
    monkeypatch.chdir(REPO)
    capsys.readouterr()
    code = main([str(item) for item in command])
    out, err = capsys.readouterr()
    assert code == 0, out[-3000:] + err[-3000:]
    return out


@pytest.mark.slow
def test_a_whole_run_on_generated_rooms_prints_the_headline(tmp_path, capsys, monkeypatch):
    data = generated_areas(tmp_path)
    before = sorted(path.name for path in data.rglob('*'))
    scans = tmp_path / 'scans'
    write_generated_scans(scans, 2)  # office_1 and lab_1, with their true boxes
    bare = make_room('L', n_points=20_000, seed=4, furniture=3)  # none of the classes
    write_scan(scans / 'bare_1.ply', bare.points)
    write_labels(scans / 'bare_1.labels.json', {
        'format': LABELS_FORMAT,
        'scan': 'bare_1.ply',
        'classes': CLASSES,
        'boxes': []
    })
    busy = tmp_path / 'fine-tune.running'
    checkpoint = initial_checkpoint(REPO / 'configs/tr3d/exp2_cpu.py',
                                    tmp_path / 'initialised.pth', CLASSES)
    finetune = tmp_path / 'teach_finetune_one_repeat.py'
    finetune.write_text(
        ONE_REPEAT_FINETUNE.format(base=REPO / 'configs' / 'tr3d' / 'teach_finetune.py'))
    command = [
        scans,
        '--train',
        'office_1',
        'bare_1',
        '--config',
        'configs/tr3d/exp2_cpu.py',
        '--checkpoint',
        checkpoint,
        '--data',
        data,
        '--data-root',
        tmp_path / 'teach_data',
        '--work',
        tmp_path / 'work',
        '--finetune-config',
        finetune,
        '--iters',
        1,
        '--busy-file',
        busy,
        # the initial model scores every box about 0.5: a few dozen parts to correct
        '--score-thr',
        0.511,
        '--fork-tools'
    ]
    out = run_from_repo(main, command, monkeypatch, capsys)
    headline = HEADLINE.fullmatch(out.strip().splitlines()[-1])
    assert headline, out[-2000:]
    assert all(math.isfinite(float(value)) for value in headline.groups())
    results = json.loads((tmp_path / 'work' / 'teach.json').read_text())
    assert results['train'] == ['office_1', 'bare_1'] and results['held_out'] == ['lab_1']
    office, empty = results['corrections']
    assert office['labels'] == len(read_labels(scans / 'office_1.labels.json')['boxes']) > 0
    assert empty['labels'] == 0
    assert (tmp_path / 'work' / 'finetune' / 'iter_1.pth').is_file() and not busy.exists()
    # the user area went into the run's data root; the generated data stayed as it was
    assert sorted(path.name for path in data.rglob('*')) == before
    assert (tmp_path / 'teach_data' / 's3dis_infos_Area_10.pkl').is_file()
    assert (tmp_path / 'teach_data' / 's3dis_infos_Area_7.pkl').is_symlink()
    for name in ('before', 'after'):
        rows = results[name]['area9']['mAP@0.25']
        assert np.isfinite(rows['mean']) and results[name]['held_out']['rooms'] == 1
