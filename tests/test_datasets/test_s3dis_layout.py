"""The real S3DIS layout: areas 1-6 in S3DIS naming with the known stray byte of
``Area_5/hallway_6``, converted with tools/create_data.py and counted by tools/dataset_stats.py
(Table 1 with its S3DIS rows), and create_data's ``--extra-tag``."""
import hashlib
import pickle
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from projects.synthdet.datasets.s3dis_repairs import repaired_point_text
from tests.s3dis_fixtures import (HALLWAY_CEILING, S3DIS_DIR, S3DIS_OBJECTS, STRAY_LINE,
                                  STRAY_OFFSET, STRAY_POINT, write_hallway_6, write_synthetic_area)
from tests.test_tools.test_tr3d_tools import load_tool

TABLE1_REAL = ('chair', 'table', 'sofa', 'bookcase', 'board')


@pytest.fixture(scope='module')
def s3dis(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """Areas 1-6 (one room each, S3DIS names, plus hallway_6 in area 5) and a generated area 7."""
    root = tmp_path_factory.mktemp('s3dis_layout')
    truth = {}
    for area in range(1, 7):
        truth[area] = write_synthetic_area(
            root, area, n_rooms=1, seed=area, classes=S3DIS_OBJECTS, points_per_object=60)
    truth[7] = write_synthetic_area(root, 7, n_rooms=1, seed=7, points_per_object=60)
    ceiling_points = write_hallway_6(root / S3DIS_DIR)
    ceiling = root / S3DIS_DIR / Path(*HALLWAY_CEILING)
    counts = {
        area: Counter(box['class'] for boxes in rooms.values() for box in boxes)
        for area, rooms in truth.items()
    }
    counts[5]['chair'] += 1  # hallway_6
    return dict(
        root=root,
        counts=counts,
        ceiling=ceiling,
        ceiling_sha=hashlib.sha256(ceiling.read_bytes()).hexdigest(),
        ceiling_points=ceiling_points)


def test_create_data_repairs_the_hallway_6_stray_byte(s3dis: dict, tmp_path: Path,
                                                      capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / 'data'
    assert load_tool('create_data').main(
        ['s3dis', '--root-path', str(s3dis['root']), '--out-dir',
         str(out)]) == 0
    report = capsys.readouterr().out
    assert f'repaired the known stray byte of {s3dis["ceiling"]}' in report
    assert 'skipped' not in report
    points = np.fromfile(out / 'points' / 'Area_5_hallway_6.bin', dtype=np.float32).reshape(-1, 6)
    assert len(points) == s3dis['ceiling_points'] + 50  # no line dropped
    # the converter shifts the room's minimum to 0; the repaired line is the ceiling's 180389th
    minimum = np.fromfile(s3dis['ceiling'].with_name('chair_1.txt'), sep=' ').reshape(-1, 6)
    shift = np.minimum(minimum[:, :3].min(axis=0), [1.0, 1.0, 3.0])
    np.testing.assert_allclose(
        points[STRAY_LINE - 1, :3], np.array(STRAY_POINT[:3]) - shift, atol=1e-5)
    np.testing.assert_array_equal(points[STRAY_LINE - 1, 3:], STRAY_POINT[3:])
    assert hashlib.sha256(s3dis['ceiling'].read_bytes()).hexdigest() == s3dis['ceiling_sha']


def test_repair_only_touches_the_known_defect(s3dis: dict, tmp_path: Path) -> None:
    repaired = repaired_point_text(s3dis['ceiling'])
    original = s3dis['ceiling'].read_bytes()
    assert len(repaired) == len(original)
    assert [i for i in range(len(original)) if original[i] != repaired[i]] == [STRAY_OFFSET]
    assert repaired[STRAY_OFFSET:STRAY_OFFSET + 1] == b' '
    fixed = tmp_path / Path(*HALLWAY_CEILING)  # a copy already fixed by hand or by mmdet3d
    fixed.parent.mkdir(parents=True)
    fixed.write_bytes(repaired)
    assert repaired_point_text(fixed) is None
    assert repaired_point_text(s3dis['ceiling'].with_name('chair_1.txt')) is None


def test_table1_prints_the_s3dis_rows(s3dis: dict, tmp_path: Path,
                                      capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / 'data'
    assert load_tool('create_data').main([
        's3dis', '--root-path',
        str(s3dis['root']), '--out-dir',
        str(out), '--extra-tag', 'realtag', '--workers', '2'
    ]) == 0
    assert sorted(
        p.name for p in out.glob('*.pkl')) == [f'realtag_infos_Area_{a}.pkl' for a in range(1, 8)]
    with open(out / 'realtag_infos_Area_5.pkl', 'rb') as f:
        assert len(pickle.load(f)['data_list']) == 2  # office_1 and hallway_6
    capsys.readouterr()
    assert load_tool('dataset_stats').main([str(out), '--extra-tag', 'realtag']) == 0
    rows = {
        line[:20].strip(): line[20:].split()
        for line in capsys.readouterr().out.splitlines()[2:]
    }
    counts = s3dis['counts']
    for area in range(1, 7):
        assert rows[f'Area {area}'][:5] == [str(counts[area][c] or '-') for c in TABLE1_REAL]
        assert rows[f'Area {area}'][5:] == ['-', '-']
    real = [sum(counts[a][c] for a in range(1, 7)) for c in TABLE1_REAL]
    assert rows['S3DIS (areas 1-6)'] == [*map(str, real), '-', '-']
    synthetic = [counts[7][c] for c in ('chair', 'table', 'sofa')]
    assert rows['Synthetic (areas 7+)'][:3] == [*map(str, synthetic)]
    assert rows['Synthetic (areas 7+)'][3:5] == ['-', '-']
    assert rows['Synthetic (areas 7+)'][5:] == [
        str(counts[7]['yumi']), str(counts[7]['3dprinter'])
    ]
