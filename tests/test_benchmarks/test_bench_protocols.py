"""The three protocols on real scans (benchmarks/bench_protocols.py): how scans split by room and
rescan, the goals, and one whole run at a tiny scale (an untrained model, one fine-tune iteration,
one adaptation round of one iteration) through bench_teach, tools/predict.py --known,
tools/adapt.py and the evaluations."""
from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest

from benchmarks.bench_protocols import goals, main, split, summary_line
from benchmarks.bench_real_scans import write_generated_scans
from projects.synthdet.evaluation.real_scans import LabelledScan
from synthdet.contracts import read_labels, write_labels
from synthdet.scan_io import write_scan
from tests.checkpoints import initial_checkpoint
from tests.room_scans import make_room
from tests.test_benchmarks.test_bench_teach import (ONE_REPEAT_FINETUNE, generated_areas,
                                                     run_from_repo)

REPO = Path(__file__).resolve().parents[2]
CLASSES = ['table', 'chair', 'sofa', 'yumi', '3dprinter']
SUMMARY = re.compile(r'(teach, next scan|known objects, next scan|teach, new room|'
                     r'adapt, unlabelled): recall \d\.\d\d '
                     r'\(was \d\.\d\d\), \d+\.\d false positives per scan \(was \d+\.\d\), '
                     r'\d+ phantom')


def scan(stem: str) -> LabelledScan:
    return LabelledScan(Path(f'{stem}.ply'), {'boxes': []})


def test_scans_split_by_room_and_rescan():
    scans = [scan(stem) for stem in ('room0_office', 'room0_rescan1', 'room0_rescan2',
                                     'room1', 'room1_rescan1', 'view5', 'room2')]
    train, test = split(scans, 'next', [])
    assert [item.scan.stem for item in train] == ['room0_office', 'room1']  # not room2
    assert [item.scan.stem for item in test] == ['room0_rescan1', 'room0_rescan2',
                                                 'room1_rescan1']
    train, test = split(scans, 'new', ['room0'])
    assert [item.scan.stem for item in train] == ['room0_office', 'room0_rescan1',
                                                  'room0_rescan2']
    assert [item.scan.stem for item in test] == ['room1', 'room1_rescan1', 'view5', 'room2']
    with pytest.raises(ValueError, match='0 scans to teach on'):
        split(scans, 'new', ['room9'])
    with pytest.raises(ValueError, match='protocol next'):
        split([scan('room0'), scan('room1')], 'next', [])


def figures(recall: float, false: float, phantoms: int, area9: float) -> dict:
    return {'held_out': {'overall_recall': recall, 'false_positives_per_room': false,
                         'phantoms': phantoms},
            'area9': {'mAP@0.25': {'table': area9, 'chair': 0.95, 'mean': 0.9}}}


def test_each_protocol_has_its_goals():
    row = {'before': figures(0.5, 4.0, 2, 0.95), 'after': figures(0.92, 0.5, 0, 0.91),
           'minutes': 20.0}
    assert all(goals('next', row).values())
    assert not goals('next', dict(row, after=figures(0.92, 0.6, 0, 0.91)))[
        '<= 0.5 false positives per scan']
    assert goals('new', row)['recall +0.15'] and goals('unlabelled', row)['recall +0.10']
    assert goals('unlabelled', row)['30 % fewer false positives']
    worse = dict(row, after=figures(0.55, 3.0, 1, 0.85), minutes=31.0)
    assert not any(goals('new', worse)[key] for key in (
        'recall +0.15', 'area 9 >= 0.9 in every class', '<= 30 minutes'))
    assert goals('new', worse)['no more false positives']
    assert not goals('unlabelled', worse)['30 % fewer false positives']  # 3.0 > 0.7 x 4.0
    assert summary_line('next', row) == ('teach, next scan: recall 0.92 (was 0.50), 0.5 false '
                                         'positives per scan (was 4.0), 0 phantom')


def labelled_rooms(folder: Path) -> None:
    """office_1 and its rescan (the same points, its own labels file), lab_1, storage_1, and an
    unlabelled scan the adaptation uses too."""
    write_generated_scans(folder, 3)
    shutil.copyfile(folder / 'office_1.ply', folder / 'office_rescan1.ply')
    labels = read_labels(folder / 'office_1.labels.json')
    write_labels(folder / 'office_rescan1.labels.json', dict(labels, scan='office_rescan1.ply'))
    write_scan(folder / 'hall_unlabelled.ply',
               make_room('rect', n_points=20_000, seed=5, furniture=3).points)


@pytest.mark.slow
def test_a_whole_run_of_the_three_protocols_prints_their_lines(tmp_path, capsys, monkeypatch):
    data = generated_areas(tmp_path)
    scans = tmp_path / 'scans'
    labelled_rooms(scans)
    checkpoint = initial_checkpoint(REPO / 'configs/tr3d/exp2_cpu.py',
                                    tmp_path / 'initialised.pth', CLASSES)
    finetune = tmp_path / 'teach_finetune_one_repeat.py'
    finetune.write_text(
        ONE_REPEAT_FINETUNE.format(base=REPO / 'configs' / 'tr3d' / 'teach_finetune.py'))
    work = tmp_path / 'work'
    command = [
        scans, '--config', 'configs/tr3d/exp2_cpu.py', '--checkpoint', checkpoint, '--data', data,
        '--work', work, '--new-rooms', 'office', '--finetune-config', finetune, '--iters', 1,
        '--rounds', 1, '--refresh', 1, '--score-thr', 0.511, '--pseudo-thr', 0.6, '--fork-tools'
    ]
    out = run_from_repo(main, command, monkeypatch, capsys)
    lines = out.strip().splitlines()[-4:]
    assert [SUMMARY.fullmatch(line).group(1) for line in lines] == [
        'teach, next scan', 'known objects, next scan', 'teach, new room',
        'adapt, unlabelled'], lines
    rows = json.loads((work / 'protocols.json').read_text())
    assert rows['next']['train'] == ['office_1'] and rows['next']['test'] == ['office_rescan1']
    # the rescan is the first scan's points: every labelled object is found again
    assert rows['known']['train'] == ['office_1'] and rows['known']['test'] == ['office_rescan1']
    assert rows['known']['after']['held_out']['overall_recall'] == 1.0
    assert rows['known']['after']['held_out']['false_positives'] == 0
    assert rows['new']['train'] == ['office_1', 'office_rescan1']
    assert rows['new']['test'] == ['lab_1', 'storage_1']
    assert 'hall_unlabelled.ply' in rows['unlabelled']['train']
    assert rows['unlabelled']['test'] == ['lab_1', 'office_1', 'office_rescan1', 'storage_1']
    for row in rows.values():
        assert row['minutes'] > 0 and set(row['before']) == set(row['after']) == {
            'held_out', 'area9'}
    # the protocols' work stays in WORK; the generated data is only read
    pseudo_labels = json.loads(
        (work / 'unlabelled' / 'adapt' / 'round_1' / 'pseudo_labels.json').read_text())
    assert pseudo_labels['rule']['score_thr'] == 0.6  # --pseudo-thr is the adaptation's
    assert not any(path.name.startswith('s3dis_infos_Area_1') for path in data.iterdir())
    # the same command again reuses the adaptation; other options are refused by tools/adapt.py
    record = work / 'unlabelled' / 'adapt_time.json'
    recorded = record.read_text()
    again = [str(item) for item in command] + ['--protocols', 'unlabelled']
    assert main(again) == 0 and record.read_text() == recorded
    capsys.readouterr()
    assert main([*again, '--unsure-thr', '0.2']) == 1
    assert 'holds a run with other unsure_thr' in capsys.readouterr().err
    assert record.read_text() == recorded
