"""S3DIS-format -> mmdet3d info conversion: round trip, reader, bad inputs, CLI."""
import pickle
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from projects.synthdet.datasets.s3dis_converter import (S3DIS_DIR, WRITE_PIECE_BYTES,
                                                        S3DISLayoutError, UnknownClassWarning,
                                                        convert_s3dis, write_bin)
from synthdet.classes import DETECTION_CLASSES, SEMANTIC_CLASSES
from synthdet.point_text import PointFileError, max_rows, parse_fast, read_point_file
from tests.s3dis_fixtures import write_synthetic_area

REPO_ROOT = Path(__file__).resolve().parents[2]


def _load_room(out_dir: Path, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    points = np.fromfile(out_dir / 'points' / f'{name}.bin', dtype=np.float32).reshape(-1, 6)
    instance = np.fromfile(out_dir / 'instance_mask' / f'{name}.bin', dtype=np.int64)
    semantic = np.fromfile(out_dir / 'semantic_mask' / f'{name}.bin', dtype=np.int64)
    return points, instance, semantic


def _line_count(path: Path) -> int:
    return sum(1 for line in path.read_text().splitlines() if line.strip())


def _outputs(out_dir: Path) -> list[str]:
    return sorted(str(p.relative_to(out_dir)) for p in out_dir.rglob('*') if p.is_file())


@pytest.fixture(scope='module')
def converted(tmp_path_factory):
    root = tmp_path_factory.mktemp('s3dis')
    truth = {
        area:
        write_synthetic_area(
            root, area, n_rooms=3, seed=area, points_per_object=150, classes=DETECTION_CLASSES)
        for area in (2, 7)
    }
    summary = convert_s3dis(root, root)
    return root, truth, summary


def test_round_trip_boxes_masks_and_info_format(converted):
    root, truth, summary = converted
    assert summary.rooms_per_area == {2: 3, 7: 3}
    assert not summary.skipped and not summary.unknown_classes
    for area, rooms in truth.items():
        infos = pickle.loads((root / f's3dis_infos_Area_{area}.pkl').read_bytes())
        assert infos['metainfo'] == {
            'categories': {
                c: i
                for i, c in enumerate(DETECTION_CLASSES)
            },
            'dataset': 's3dis',
            'info_version': '1.1'
        }
        assert [i['sample_idx'] for i in infos['data_list']] == list(range(len(rooms)))
        for info, room in zip(infos['data_list'], sorted(rooms)):
            name = f'Area_{area}_{room}'
            assert info['lidar_points'] == {'num_pts_feats': 6, 'lidar_path': f'{name}.bin'}
            assert info['pts_instance_mask_path'] == f'{name}.bin'
            assert info['pts_semantic_mask_path'] == f'{name}.bin'
            room_dir = root / S3DIS_DIR / f'Area_{area}' / room
            points, instance, semantic = _load_room(root, name)
            # masks and points match the annotation files line for line
            ann_files = sorted(
                (room_dir / 'Annotations').glob('*.txt'),
                key=lambda p: (p.stem.split('_')[0], int(p.stem.split('_')[1])))
            assert len(points) == len(instance) == len(semantic) == _line_count(
                room_dir / f'{room}.txt')
            assert np.array_equal(np.bincount(instance)[1:], [_line_count(p) for p in ann_files])
            for k, path in enumerate(ann_files, start=1):
                assert set(
                    semantic[instance == k]) == {SEMANTIC_CLASSES.index(path.stem.split('_')[0])}
            # the shift: room minimum at 0, colors kept
            raw = np.loadtxt(room_dir / f'{room}.txt')
            assert np.allclose(points[:, :3].min(axis=0), 0.0)
            assert np.allclose(np.sort(points[:, 3]), np.sort(raw[:, 3]))
            shift = raw[:, :3].min(axis=0)
            # boxes: min/max of the instance points, equal to the fixture's true boxes
            got = [(inst['bbox_label_3d'], inst['bbox_3d']) for inst in info['instances']]
            assert len(got) == len(rooms[room])
            for box in rooms[room]:
                centre = (np.add(box['min'], box['max']) / 2 - shift)
                size = np.subtract(box['max'], box['min'])
                assert (DETECTION_CLASSES.index(box['class']),
                        True) in [(label, np.allclose(bbox, np.r_[centre, size], atol=1e-5))
                                  for label, bbox in got]
            detection_ids = [
                k for k, p in enumerate(ann_files, start=1)
                if p.stem.split('_')[0] in DETECTION_CLASSES
            ]
            for inst, k in zip(info['instances'], detection_ids):
                xyz = points[instance == k, :3]
                lo, hi = xyz.min(axis=0), xyz.max(axis=0)
                assert inst['bbox_3d'] == np.concatenate([(lo + hi) / 2, hi - lo]).tolist()
    assert summary.num_points == sum(
        len(_load_room(root, f'Area_{a}_{r}')[0]) for a, rooms in truth.items() for r in rooms)
    assert summary.instances_per_class == {
        c: n
        for c in DETECTION_CLASSES if (n := sum(
            b['class'] == c for rooms in truth.values() for bs in rooms.values() for b in bs))
    }


def test_workers_give_identical_outputs(converted, tmp_path):
    root, _, _ = converted
    convert_s3dis(root, tmp_path, areas=[7], workers=2)
    for path in (tmp_path / 'points').iterdir():
        for sub in ('points', 'instance_mask', 'semantic_mask'):
            assert (tmp_path / sub / path.name).read_bytes() == (root / sub /
                                                                 path.name).read_bytes()
    assert pickle.loads((tmp_path / 's3dis_infos_Area_7.pkl').read_bytes()) == \
        pickle.loads((root / 's3dis_infos_Area_7.pkl').read_bytes())
    assert not (tmp_path / 's3dis_infos_Area_2.pkl').exists()


def test_a_room_after_a_larger_one_converts_as_it_does_alone(tmp_path):
    """The room arrays are reused from room to room: nothing of a larger room converted before
    may reach a smaller room's outputs."""
    write_synthetic_area(tmp_path / 'big', 7, n_rooms=1, seed=8, points_per_object=900)
    write_synthetic_area(tmp_path / 'small', 7, n_rooms=1, seed=9, points_per_object=100)
    both = tmp_path / 'both' / S3DIS_DIR / 'Area_7'
    both.mkdir(parents=True)
    for source, room in (('big', 'room_1'), ('small', 'room_2')):  # natural order: big first
        (both / room).symlink_to(tmp_path / source / S3DIS_DIR / 'Area_7' / 'office_1')
    convert_s3dis(tmp_path / 'both', tmp_path / 'out_both', workers=1)
    convert_s3dis(tmp_path / 'small', tmp_path / 'out_small', workers=1)
    together = _load_room(tmp_path / 'out_both', 'Area_7_room_2')
    alone = _load_room(tmp_path / 'out_small', 'Area_7_office_1')
    assert len(together[0]) < len(_load_room(tmp_path / 'out_both', 'Area_7_room_1')[0])
    for ours, reference in zip(together, alone):
        assert ours.tobytes() == reference.tobytes()
    infos = [
        pickle.loads((tmp_path / out / 's3dis_infos_Area_7.pkl').read_bytes())['data_list']
        for out in ('out_both', 'out_small')
    ]
    assert infos[0][1]['instances'] == infos[1][0]['instances']


@pytest.mark.parametrize('num_bytes', [0, 8, WRITE_PIECE_BYTES, 3 * WRITE_PIECE_BYTES + 24])
def test_bin_files_hold_the_array_bytes_whatever_their_size(tmp_path, num_bytes):
    array = np.arange(num_bytes // 8, dtype=np.int64)
    write_bin(array, tmp_path / 'mask.bin')
    assert (tmp_path / 'mask.bin').read_bytes() == array.tobytes()


def test_missing_area_and_layout_errors(converted, tmp_path):
    root, _, _ = converted
    with pytest.raises(S3DISLayoutError, match=r'area\(s\) \[5\]'):
        convert_s3dis(root, tmp_path, areas=[5])
    with pytest.raises(S3DISLayoutError, match='S3DIS data folder not found'):
        convert_s3dis(tmp_path, tmp_path)
    with pytest.raises(ValueError, match="on_error must be one of"):
        convert_s3dis(root, tmp_path, on_error='ignore')


def _write_points(path: Path, formats: list[str], seed: int) -> list[str]:
    rng = np.random.default_rng(seed)
    xyz, rgb = rng.uniform(-50, 50, (300, 3)), rng.integers(0, 256, (300, 3))
    lines = [
        ' '.join([formats[k % len(formats)].format(v) for v in p] + [str(v) for v in c])
        for k, (p, c) in enumerate(zip(xyz, rgb))
    ]
    lines[3] = '  .5 5. -0.0\t1 2 3e0  \r'  # odd but valid spellings
    lines.insert(10, '')  # blank lines are ignored
    path.write_text('\n'.join(lines))
    return [line for line in lines if line.strip()]


def _reference_values(lines: list[str]) -> np.ndarray:
    return np.array([[float(t) for t in line.split()] for line in lines])


def test_reader_fast_path_matches_reference_parser(tmp_path):
    path = tmp_path / 'points.txt'
    lines = _write_points(path, ['{:.3f}', '{:.6f}', '{:.4e}', '{:+.2f}', '{:.15g}'], seed=0)
    expected = _reference_values(lines)
    out = np.empty((len(lines) + 2, 6))
    rows, _ = parse_fast(np.frombuffer(path.read_bytes(), dtype=np.uint8), out)
    assert rows == len(lines)  # the compiled path accepted every line ...
    assert np.array_equal(out[:rows], expected)  # ... bit for bit like float()
    assert np.array_equal(np.signbit(out[:rows]), np.signbit(expected))
    points, bad = read_point_file(path)
    assert not bad and np.array_equal(points, expected)


def test_reader_falls_back_for_long_mantissas(tmp_path):
    path = tmp_path / 'points.txt'
    lines = _write_points(path, ['{:.17g}', '{:.3f}'], seed=1)
    out = np.empty((len(lines) + 2, 6))
    rows, line = parse_fast(np.frombuffer(path.read_bytes(), dtype=np.uint8), out)
    assert (rows, line) == (-1, 1)  # 17 significant digits: not exact in the compiled path
    points, bad = read_point_file(path)
    assert not bad and np.array_equal(points, _reference_values(lines))


@pytest.mark.parametrize('line, message', [
    ('1.0 2.0 3.0 10 20', 'expected 6 columns (x y z r g b), found 5'),
    ('1.0 2.0 3.0 10 20 30 40', 'expected 6 columns (x y z r g b), found 7'),
    ('1.0 2.0\x103.0 10 20 30', "cannot parse '2.0\\x103.0' as a number"),
    ('1.0 nan 3.0 10 20 30', "non-finite value 'nan'"),
    ('1.0 2.0 1e999 10 20 30', "non-finite value '1e999'"),
    ('1.0 2.0 3.0 10 20 300', 'color value 300 outside 0-255'),
])
def test_bad_line_raises_naming_file_and_line(tmp_path, line, message):
    path = tmp_path / 'chair_1.txt'
    path.write_text(f'0 0 0 1 2 3\n1 1 1 4 5 6\n{line}\n2 2 2 7 8 9\n')
    with pytest.raises(PointFileError) as error:
        read_point_file(path)
    assert str(error.value) == f'{path}:3: {message}'
    points, bad = read_point_file(path, skip_bad_lines=True)
    assert np.array_equal(points[:, 0], [0, 1, 2]) and [(b.line, b.reason)
                                                        for b in bad] == [(3, message)]


def test_reader_writes_into_a_given_array(tmp_path):
    path = tmp_path / 'sofa_1.txt'
    path.write_text('0 0 0 1 2 3\n1 1 1 4 5 6 7\n2 2 2 7 8 9\n')
    out = np.full((max_rows(path.stat().st_size) + 5, 6), -1.0)
    points, bad = read_point_file(path, skip_bad_lines=True, out=out[5:])  # reference path
    assert np.shares_memory(points, out) and np.array_equal(out[5:7, 0], [0, 2])
    assert [b.line for b in bad] == [2] and np.all(out[:5] == -1.0)
    with pytest.raises(ValueError, match='too small'):
        read_point_file(path, out=np.empty((2, 6)))


def test_empty_file_raises(tmp_path):
    path = tmp_path / 'table_1.txt'
    path.write_text('')
    with pytest.raises(PointFileError, match=f'{path}:1: file is empty'):
        read_point_file(path, skip_bad_lines=True)


def _area_with_defects(root: Path) -> Path:
    write_synthetic_area(root, 1, n_rooms=2, seed=3, points_per_object=60)
    ann_dir = root / S3DIS_DIR / 'Area_1' / 'lab_1' / 'Annotations'
    chair = ann_dir / 'chair_1.txt'
    lines = chair.read_text().splitlines()
    lines[4] = lines[4].replace(' ', '\x10', 1)  # the kind of stray byte real S3DIS has
    chair.write_text('\n'.join(lines) + '\n')
    (ann_dir / 'board_1.txt').write_text('')
    return chair


def test_bad_input_raise_leaves_nothing_behind(tmp_path):
    chair = _area_with_defects(tmp_path / 'in')
    write_synthetic_area(tmp_path / 'in', 7, n_rooms=1, seed=4, points_per_object=60)
    out = tmp_path / 'out'
    for workers in (1, 2):
        with pytest.raises(PointFileError, match=f'{chair.parent}/board_1.txt:1: file is empty'):
            convert_s3dis(tmp_path / 'in', out, workers=workers)
        assert _outputs(out) == []  # Area_1 fails first: no partial or final file stays
    (chair.parent / 'board_1.txt').unlink()
    for workers in (1, 2):
        with pytest.raises(PointFileError, match=f"{chair}:5: cannot parse '.*' as a number"):
            convert_s3dis(tmp_path / 'in', out, workers=workers)
        assert _outputs(out) == []


def test_bad_input_skip_reports_and_converts_the_rest(tmp_path):
    chair = _area_with_defects(tmp_path / 'in')
    summary = convert_s3dis(tmp_path / 'in', tmp_path / 'out', on_error='skip')
    skipped = [(Path(s.path).name, s.line) for s in summary.skipped]
    assert skipped == [('board_1.txt', None), ('chair_1.txt', 5)]
    assert 'file is empty' in summary.report() and f'{chair}:5:' in summary.report()
    points, instance, _ = _load_room(tmp_path / 'out', 'Area_1_lab_1')
    ann_dir = chair.parent
    assert len(points) == sum(_line_count(p) for p in ann_dir.glob('*.txt')) - 1
    assert instance.max() == len(list(ann_dir.glob('*.txt'))) - 1  # the empty file is left out
    assert not [p for p in _outputs(tmp_path / 'out') if p.endswith('.partial')]


def test_unknown_classes_become_clutter_with_one_warning(tmp_path):
    write_synthetic_area(
        tmp_path, 3, n_rooms=2, seed=5, points_per_object=60, classes=('table', 'stairs', 'chair'))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter('always')
        summary = convert_s3dis(tmp_path, tmp_path)
    unknown = [w for w in caught if issubclass(w.category, UnknownClassWarning)]
    assert len(unknown) == 1 and 'stairs' in str(unknown[0].message)
    assert len(summary.unknown_classes['stairs']) >= 2
    for room in ('office_1', 'lab_1'):
        _, instance, semantic = _load_room(tmp_path, f'Area_3_{room}')
        ann_files = sorted(
            (tmp_path / S3DIS_DIR / 'Area_3' / room / 'Annotations').glob('*.txt'),
            key=lambda p: (p.stem.split('_')[0], int(p.stem.split('_')[1])))
        stairs_ids = [k for k, p in enumerate(ann_files, 1) if p.stem.startswith('stairs')]
        assert stairs_ids and all(
            set(semantic[instance == k]) == {SEMANTIC_CLASSES.index('clutter')}
            for k in stairs_ids)


def test_cli_reports_errors_and_summaries(tmp_path):
    chair = _area_with_defects(tmp_path)
    command = [
        sys.executable,
        str(REPO_ROOT / 'tools' / 'create_data.py'), 's3dis', '--root-path',
        str(tmp_path), '--out-dir',
        str(tmp_path / 'out')
    ]
    failed = subprocess.run(command, capture_output=True, text=True, cwd=tmp_path)
    assert failed.returncode == 2, failed.stderr  # bad input
    assert f'{chair.parent}/board_1.txt:1: file is empty' in failed.stderr
    done = subprocess.run(
        command + ['--on-error', 'skip', '--areas', '1'],
        capture_output=True,
        text=True,
        cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert 'converted 2 rooms (Area_1: 2)' in done.stdout and 'skipped 2 input(s)' in done.stdout
    assert (tmp_path / 'out' / 's3dis_infos_Area_1.pkl').is_file()
