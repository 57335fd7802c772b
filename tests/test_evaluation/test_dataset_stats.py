"""Table 1 statistics counted from converted info pickles."""
import json
import math
import pickle
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest

from projects.synthdet.datasets.s3dis_converter import convert_s3dis, info_metainfo
from projects.synthdet.evaluation.table1 import (TABLE1_CLASSES, count_instances, format_table1,
                                                 table1, table1_rows)
from synthdet.classes import S3DIS_DETECTION_CLASSES
from tests.s3dis_fixtures import write_synthetic_area

REPO_ROOT = Path(__file__).resolve().parents[2]


def test_counts_from_converted_fixture_match_the_written_objects(tmp_path):
    truth = {
        1:
        write_synthetic_area(tmp_path, 1, 2, seed=11, points_per_object=40,
                             classes=S3DIS_DETECTION_CLASSES),
        8:
        write_synthetic_area(tmp_path, 8, 3, seed=12, points_per_object=40)
    }
    convert_s3dis(tmp_path, tmp_path)
    counts = count_instances(tmp_path)
    assert counts == {
        area: Counter(b['class'] for boxes in rooms.values() for b in boxes)
        for area, rooms in truth.items()
    }
    assert count_instances(tmp_path, areas=[8]) == {8: counts[8]}


def write_infos(root: Path, area: int, labels_per_room: list[list[int]]) -> None:
    data_list = [{
        'sample_idx': i,
        'instances': [{
            'bbox_3d': [0.0] * 6,
            'bbox_label_3d': label
        } for label in labels]
    } for i, labels in enumerate(labels_per_room)]
    with open(root / f's3dis_infos_Area_{area}.pkl', 'wb') as f:
        pickle.dump({'metainfo': info_metainfo(), 'data_list': data_list}, f)


def test_table1_rows_and_cli_on_known_counts(tmp_path):
    # label ids: table 0, chair 1, sofa 2, bookcase 3, board 4, yumi 5, 3dprinter 6
    write_infos(tmp_path, 2, [[1, 1, 0], [1, 3, 4, -1]])  # 3 chairs, 1 table, bookcase, board
    write_infos(tmp_path, 5, [[1]])
    write_infos(tmp_path, 9, [[1, 5, 5, 6], [0, 0, 0]])
    rows = dict(table1_rows(count_instances(tmp_path)))
    assert list(rows) == [
        'Area 2', 'Area 5', 'Area 9', 'S3DIS (areas 1-6)', 'Synthetic (areas 7+)', 'Total',
        'Synthetic share %'
    ]
    assert TABLE1_CLASSES == ('chair', 'table', 'sofa', 'bookcase', 'board', 'yumi', '3dprinter')
    assert rows['Area 2'] == [3, 1, 0, 1, 1, 0, 0]
    assert rows['S3DIS (areas 1-6)'] == [4, 1, 0, 1, 1, 0, 0]
    assert rows['Synthetic (areas 7+)'] == [1, 3, 0, 0, 0, 2, 1]
    assert rows['Total'] == [5, 4, 0, 1, 1, 2, 1]
    share = rows['Synthetic share %']
    assert share[:2] == [20.0, 75.0] and math.isnan(
        share[2]) and share[3:] == [0.0, 0.0, 100.0, 100.0]
    document = table1(count_instances(tmp_path))
    assert document['format'] == 'synthdet.table1/1' and document['areas'] == [2, 5, 9]
    assert document['rows'][-1] == {
        'label': 'Synthetic share %',
        'values': [20.0, 75.0, None, 0.0, 0.0, 100.0, 100.0]
    }
    text = format_table1(json.loads(json.dumps(document)))
    assert text.splitlines()[-1].split() == [
        'Synthetic', 'share', '%', '20.0', '75.0', '-', '0.0', '0.0', '100.0', '100.0'
    ]
    out = tmp_path / 'tables' / 'table1.json'
    done = subprocess.run([
        sys.executable,
        str(REPO_ROOT / 'tools' / 'dataset_stats.py'),
        str(tmp_path), '--areas', '2', '9', '--out',
        str(out)
    ],
                          capture_output=True,
                          text=True)
    assert done.returncode == 0, done.stderr
    written = (tmp_path / 'tables' / 'table1.txt').read_text()
    assert written.startswith('Table 1') and written in done.stdout
    assert written.splitlines()[-2].split() == ['Total', '4', '4', '-', '1', '1', '2', '1']
    assert json.loads(out.read_text())['areas'] == [2, 9]
    missing = subprocess.run([
        sys.executable,
        str(REPO_ROOT / 'tools' / 'dataset_stats.py'),
        str(tmp_path), '--areas', '4'
    ],
                             capture_output=True,
                             text=True)
    assert missing.returncode == 2  # bad input
    assert 's3dis_infos_Area_4.pkl: info pickle not found' in missing.stderr


def test_no_pickles_is_an_error(tmp_path):
    with pytest.raises(FileNotFoundError, match='no s3dis_infos_Area_N.pkl'):
        count_instances(tmp_path)
