"""Scan readers and info pickles that are safe with any file a user hands over.

PCD ``binary_compressed`` (written here by Open3D) reads to the same points as its binary twin
and a damaged one is one line naming the file; header point counts that the data does not hold
are an error; text lines are read in bounded memory and one longer than the limit is refused
with its line number; an info pickle that would run code is refused by the dataset and by
``tools/test.py``, ``tools/train.py`` and ``tools/dataset_stats.py`` without running it.
"""
import os
import pickle
import subprocess
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import open3d as o3d
import pytest

from synthdet import scan_io
from synthdet.info_files import InfoFileError, load_info_pickle
from synthdet.scan_io import ScanFormatError, load_scan, read_scan, read_scan_chunks, write_scan

REPO = Path(__file__).resolve().parents[2]
TINY = REPO / 'configs' / 'tr3d' / 'tiny.py'


def run(*args: object, timeout: float = 600) -> subprocess.CompletedProcess:
    """Run ``python ARGS...`` from the repository root with one OpenMP thread."""
    return subprocess.run([sys.executable, *map(str, args)],
                          cwd=REPO,
                          capture_output=True,
                          text=True,
                          timeout=timeout,
                          env={**os.environ, 'OMP_NUM_THREADS': '1'})


def assert_one_line_error(proc: subprocess.CompletedProcess, code: int, *fragments: str) -> None:
    """Exit ``code``, no traceback, and one stderr line holding every fragment."""
    assert proc.returncode == code, proc.stderr[-3000:]
    assert 'Traceback' not in proc.stderr, proc.stderr[-3000:]
    lines = [line for line in proc.stderr.splitlines() if all(f in line for f in fragments)]
    assert len(lines) == 1, proc.stderr[-3000:]


# ------------------------------------------------------------------ PCD binary_compressed


def _open3d_pcd_pair(folder: Path, points: int = 6000) -> tuple[Path, Path]:
    """The same cloud (with normals, so fields are skipped) as binary and binary_compressed
    PCD files written by Open3D; repeated points and colors give long LZF back references."""
    rng = np.random.default_rng(4)
    xyz = np.round(rng.uniform(-2.0, 6.0, (points, 3)), 2)
    xyz[::3] = xyz[0]  # one point repeated: runs the compressor replaces by back references
    colors = rng.integers(0, 256, (points, 3)) / 255.0
    colors[points // 2:] = 0.5
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz))
    cloud.normals = o3d.utility.Vector3dVector(rng.normal(size=(points, 3)))
    cloud.colors = o3d.utility.Vector3dVector(colors)
    paths = folder / 'binary.pcd', folder / 'compressed.pcd'
    for path, compressed in zip(paths, (False, True)):
        assert o3d.io.write_point_cloud(str(path), cloud, write_ascii=False, compressed=compressed)
    return paths


def _data_offset(path: Path) -> int:
    """Bytes before the two sizes of a binary_compressed PCD (after the DATA line)."""
    content = path.read_bytes()
    return content.index(b'DATA binary_compressed\n') + len(b'DATA binary_compressed\n')


def test_binary_compressed_pcd_reads_to_the_points_of_its_binary_twin(tmp_path):
    binary, compressed = _open3d_pcd_pair(tmp_path)
    header = compressed.read_bytes()[:_data_offset(compressed)].decode()
    assert 'FIELDS x y z normal_x normal_y normal_z rgb' in header
    sizes = np.frombuffer(compressed.read_bytes(), '<u4', 2, _data_offset(compressed))
    assert sizes[0] < 0.8 * sizes[1]  # really compressed: back references
    expected = read_scan(binary)
    assert expected.shape == (6000, 6) and len(np.unique(expected[:, 3:], axis=0)) > 100
    np.testing.assert_array_equal(read_scan(compressed), expected)
    for chunk_points in (1, 7, 1000, 5999, 6000, 10_000):
        chunks = list(read_scan_chunks(compressed, chunk_points=chunk_points))
        assert max(len(chunk) for chunk in chunks) == min(chunk_points, 6000)
        np.testing.assert_array_equal(np.concatenate(chunks), expected)
    loaded = load_scan(compressed, voxel=0.05, chunk_points=500)
    np.testing.assert_array_equal(loaded.points,
                                  load_scan(binary, voxel=0.05, chunk_points=500).points)


def test_damaged_binary_compressed_pcd_is_one_line_naming_the_file(tmp_path):
    _, good = _open3d_pcd_pair(tmp_path, points=2000)
    content = good.read_bytes()
    start = _data_offset(good)
    compressed_size, size = np.frombuffer(content, '<u4', 2, start)

    def variant(name: str, data: bytes) -> Path:
        path = tmp_path / f'{name}.pcd'
        path.write_bytes(data)
        return path

    def with_sizes(compressed: int, uncompressed: int, data: bytes = content[start + 8:]) -> bytes:
        return content[:start] + np.array([compressed, uncompressed], '<u4').tobytes() + data

    cases = {
        variant('short', content[:-100]): 'shorter than the binary_compressed data its header',
        variant('no_sizes', content[:start + 5]): 'shorter than the binary_compressed data',
        variant('size', with_sizes(compressed_size, size - 28)):
        f'the header counts 2,000 points (56,000 bytes) but the binary_compressed data holds '
        f'{size - 28:,} bytes',
        # the first instruction made a back reference: before the start of the data
        variant('reference', content[:start + 8] + b'\xe0\x00' + content[start + 10:]):
        'corrupt binary_compressed data (a back reference before the start of the data, '
        'compressed byte 0)',
        variant('cut', with_sizes(compressed_size - 1, size)):
        'corrupt binary_compressed data (the data ends inside an instruction',
        variant('literal', with_sizes(33 * 2000, size, b'\x1f' * 33 * 2000)):  # 64,000 bytes
        'binary_compressed data longer than the 56,000 bytes its header gives',
    }
    for path, message in cases.items():
        with pytest.raises(ScanFormatError) as error:
            read_scan(path)
        assert str(error.value).startswith(f'{path}: ') and message in str(error.value)
        assert '\n' not in str(error.value)
    # the command lines: exit 2 with that line, before any model is loaded
    damaged = tmp_path / 'reference.pcd'
    proc = run('tools/predict.py', TINY, tmp_path / 'missing.pth', damaged, '--out',
               tmp_path / 'never')
    assert_one_line_error(proc, 2, str(damaged), 'back reference before the start')
    assert not (tmp_path / 'never').exists()
    proc = run('-m', 'configurator', 'corners', damaged, '--out', tmp_path / 'corners.json')
    assert_one_line_error(proc, 2, str(damaged), 'back reference before the start')


# ------------------------------------------------------------------ header point counts


def test_header_counting_more_points_than_the_data_holds_is_an_error(tmp_path):
    rng = np.random.default_rng(0)
    points = np.hstack([rng.uniform(0, 5, (1000, 3)), rng.integers(0, 256, (1000, 3))])
    write_scan(tmp_path / 'whole.las', points)
    content = (tmp_path / 'whole.las').read_bytes()
    (tmp_path / 'short.las').write_bytes(content[:-26 * 100])  # 100 whole records of 26 bytes
    with pytest.raises(ScanFormatError, match=r'short\.las: the header counts 1,000 points but '
                       r'the data holds 900$'):
        read_scan(tmp_path / 'short.las')
    (tmp_path / 'cut.las').write_bytes(content[:-10])  # a record cut in the middle
    with pytest.raises(ScanFormatError, match=r'cut\.las: cannot decode the 1,000 points its '
                       r'header counts'):
        read_scan(tmp_path / 'cut.las')
    header = ('VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {n}\n'
              'HEIGHT 1\nPOINTS {n}\nDATA ascii\n')
    lines = ''.join(f'{x} {y} {z}\n' for x, y, z in points[:3, :3])
    (tmp_path / 'short.pcd').write_text(header.format(n=5) + lines)
    with pytest.raises(ScanFormatError, match=r'short\.pcd: the header counts 5 points but the '
                       r'data holds 3 lines of points'):
        read_scan(tmp_path / 'short.pcd')
    (tmp_path / 'long.pcd').write_text(header.format(n=2) + lines)
    with pytest.raises(ScanFormatError, match=r'long\.pcd: the header counts 2 points but the '
                       r'data holds 3'):
        read_scan(tmp_path / 'long.pcd')
    (tmp_path / 'exact.pcd').write_text(header.format(n=3) + lines)
    np.testing.assert_allclose(read_scan(tmp_path / 'exact.pcd')[:, :3], points[:3, :3],
                               rtol=1e-6)
    binary = header.format(n=5).replace('ascii', 'binary').encode()
    (tmp_path / 'short_binary.pcd').write_bytes(
        binary + points[:3, :3].astype('<f4').tobytes())
    with pytest.raises(ScanFormatError, match=r'short_binary\.pcd: \d+ bytes, the header '
                       r'promises 5 points'):
        read_scan(tmp_path / 'short_binary.pcd')
    (tmp_path / 'words.pcd').write_text(header.format(n='many') + lines)
    with pytest.raises(ScanFormatError, match=r"words\.pcd: PCD header WIDTH 'many' is not a "):
        read_scan(tmp_path / 'words.pcd')


# ------------------------------------------------------------------ long text lines


TEXT_SCANS = {
    'scan.xyz': ('{:.3f} {:.3f} {:.3f} 10 20 30\n', 0),
    'scan.csv': ('{:.3f},{:.3f},{:.3f}\n', 1),
    'scan.pts': ('{:.3f} {:.3f} {:.3f} 5 1 2 3\n', 1),
    'scan.txt': ('{:.3f} {:.3f} {:.3f} 1 2 3\n', 0),
    'scan.pcd': ('{:.3f} {:.3f} {:.3f}\n', 11),
}
HEADERS = {
    'scan.csv': 'x,y,z\n',
    'scan.pts': '{n}\n',
    'scan.pcd': ('# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n'
                 'WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA ascii\n'),
}


def _text_scan(path: Path, points: int, long_line: int | None = None,
               long_bytes: int = 0) -> None:
    """A text scan of ``points`` lines; line ``long_line`` of the file is ``long_bytes`` long
    (without its line end), padded with spaces after its numbers."""
    line, header_lines = TEXT_SCANS[path.name]
    rows = [line.format(i * 0.01, 1.0, 2.0) for i in range(points)]
    text = HEADERS.get(path.name, '').format(n=points)
    if long_line is not None:
        index = long_line - 1 - header_lines
        rows[index] = rows[index][:-1].ljust(long_bytes) + '\n'
    path.write_text(text + ''.join(rows))


def _peak_bytes(read) -> int:
    """Peak bytes allocated by Python and numpy while ``read()`` runs."""
    tracemalloc.start()
    try:
        read()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.mark.parametrize('name', sorted(TEXT_SCANS))
def test_a_text_line_longer_than_the_limit_is_refused_in_bounded_memory(
        tmp_path, monkeypatch, name):
    monkeypatch.setattr(scan_io.common, 'MAX_LINE_BYTES', 4096)  # the limit every format reads
    path = tmp_path / name
    header_lines = TEXT_SCANS[name][1]
    _text_scan(path, 20_000, long_line=header_lines + 15_001, long_bytes=4096)
    assert len(read_scan_chunks_joined(path, 512)) == 20_000  # at the limit: read
    assert len(read_scan(path)) == 20_000
    _text_scan(path, 20_000, long_line=header_lines + 15_001, long_bytes=4097)
    with pytest.raises(ScanFormatError, match=rf'{path.name}:{header_lines + 15_001}: line '
                       r'longer than 4,096 bytes; a text scan holds one point a line'):
        read_scan_chunks_joined(path, 512)
    # a file of one 3 MB line without line end: refused having held about the limit
    line = TEXT_SCANS[name][0].format(1, 2, 3)[:-1]
    path.write_bytes(HEADERS.get(name, '').format(n=1).encode() +
                     (line + ' ' * 3_000_000).encode())
    peak = _peak_bytes(lambda: pytest.raises(ScanFormatError, read_scan_chunks_joined, path, 512))
    assert peak < 300_000, f'{peak:,} bytes to refuse a 3 MB line'
    with pytest.raises(ScanFormatError, match=rf'{path.name}:{header_lines + 1}: line longer'):
        read_scan(path)


def read_scan_chunks_joined(path: Path, chunk_points: int) -> np.ndarray:
    """The chunks of ``read_scan_chunks``, each at most ``chunk_points`` points, joined."""
    chunks = list(read_scan_chunks(path, chunk_points=chunk_points))
    assert max(len(chunk) for chunk in chunks) <= chunk_points
    return np.concatenate(chunks)


def test_a_long_line_is_one_line_from_the_command_line(tmp_path):
    scan = tmp_path / 'scan.xyz'
    _text_scan(scan, 3000, long_line=2001, long_bytes=scan_io.MAX_LINE_BYTES + 1)
    proc = run('-m', 'configurator', 'corners', scan, '--out', tmp_path / 'corners.json')
    assert_one_line_error(proc, 2, f'{scan}:2001: line longer than 1,048,576 bytes')
    assert not (tmp_path / 'corners.json').exists()


# ------------------------------------------------------------------ info pickles


class _OpensMarker:
    """Unpickling this object calls ``open(marker, 'w')``: a stand-in for any hidden code."""

    def __init__(self, marker: Path):
        self.marker = str(marker)

    def __reduce__(self):
        return open, (self.marker, 'w')


def _malicious_data_root(folder: Path, marker: Path) -> Path:
    """A data folder whose area-1 info pickle creates ``marker`` when fully unpickled."""
    folder.mkdir(parents=True)
    infos = {
        'metainfo': {'dataset': 's3dis'},
        'data_list': [{'lidar_points': {'lidar_path': 'Area_1_office_1.bin'},
                       'payload': _OpensMarker(marker)}],
    }
    (folder / 's3dis_infos_Area_1.pkl').write_bytes(pickle.dumps(infos))
    return folder


def test_the_malicious_info_pickle_really_runs_code_in_mmengine_load(tmp_path):
    from mmengine.fileio import load
    data = _malicious_data_root(tmp_path / 'data', tmp_path / 'PROBE')
    load(data / 's3dis_infos_Area_1.pkl')  # what mmdet3d's dataset reads its ann_file with
    assert (tmp_path / 'PROBE').exists()  # so a missing MARKER below means: refused


def test_the_dataset_reads_its_info_pickle_as_plain_data(tmp_path):
    from projects.synthdet.datasets.synthdet_s3dis import SynthdetS3DISDataset
    marker = tmp_path / 'MARKER'
    data = _malicious_data_root(tmp_path / 'data', marker)
    with pytest.raises(InfoFileError, match=f'{data}/s3dis_infos_Area_1.pkl: not an info '
                       r'pickle of tools/create_data.py \(io.open is not plain data\)'):
        SynthdetS3DISDataset(str(data) + '/', 's3dis_infos_Area_1.pkl', pipeline=[])
    assert not marker.exists()
    good = {'metainfo': {'dataset': 's3dis', 'info_version': '1.1'},
            'data_list': [{'sample_idx': 0, 'lidar_points': {'num_pts_feats': 6,
                                                             'lidar_path': 'Area_1_a.bin'},
                           'instances': [{'bbox_3d': [1.0, 2.0, 0.5, 0.4, 0.4, 1.0],
                                          'bbox_label_3d': 1}],
                           'pts_semantic_mask_path': 'Area_1_a.bin',
                           'pts_instance_mask_path': 'Area_1_a.bin'}]}
    (data / 'good.pkl').write_bytes(pickle.dumps(good))
    dataset = SynthdetS3DISDataset(str(data) + '/', 'good.pkl', pipeline=[],
                                   metainfo=dict(classes=('table', 'chair')))
    assert len(dataset) == 1 and dataset.metainfo['info_version'] == '1.1'
    info = dataset.get_data_info(0)
    assert info['lidar_points']['lidar_path'] == f'{data}/points/Area_1_a.bin'
    assert info['ann_info']['gt_labels_3d'].tolist() == [1]
    broken = dict(good, data_list=[{'sample_idx': 0}])
    (data / 'broken.pkl').write_bytes(pickle.dumps(broken))
    with pytest.raises(InfoFileError, match=r'broken\.pkl: data_list\[0\] is not an info of '
                       r'tools/create_data.py \(KeyError'):
        SynthdetS3DISDataset(str(data) + '/', 'broken.pkl', pipeline=[])
    for name, content in (('missing.pkl', None), ('list.pkl', pickle.dumps([1, 2])),
                          ('huge.pkl', b'\x80\x04\x8e' + (1 << 60).to_bytes(8, 'little'))):
        if content is not None:
            (data / name).write_bytes(content)
        with pytest.raises(InfoFileError, match=f'{data / name}: '):
            load_info_pickle(data / name)


def _fresh_checkpoint(path: Path) -> Path:
    """A checkpoint of the tiny config's model with its initial weights."""
    import torch
    from mmdet3d.registry import MODELS
    from mmengine.config import Config
    from mmengine.registry import init_default_scope
    cfg = Config.fromfile(str(TINY))
    init_default_scope(cfg.default_scope)
    torch.save({'meta': {}, 'state_dict': MODELS.build(cfg.model).state_dict()}, path)
    return path


@pytest.mark.slow
def test_no_tool_runs_the_code_of_an_info_pickle(tmp_path):
    marker = tmp_path / 'MARKER'
    data = _malicious_data_root(tmp_path / 'data', marker)
    evil = data / 's3dis_infos_Area_1.pkl'
    options = [
        f'train_dataloader.dataset.dataset.datasets.0.data_root={data}/',
        f'val_dataloader.dataset.data_root={data}/', f'test_dataloader.dataset.data_root={data}/'
    ]
    checkpoint = _fresh_checkpoint(tmp_path / 'fresh.pth')
    commands = {
        'test': ['tools/test.py', TINY, checkpoint, '--work-dir', tmp_path / 'test',
                 '--cfg-options', *options],
        'train': ['tools/train.py', TINY, '--work-dir', tmp_path / 'train', '--cfg-options',
                  *options, 'train_cfg.max_epochs=1'],
        'dataset_stats': ['tools/dataset_stats.py', data],
    }
    for name, command in commands.items():
        proc = run(*command)
        assert not marker.exists(), f'{name} ran the code in the info pickle'
        assert_one_line_error(proc, 2, str(evil), 'not an info pickle')


@pytest.mark.parametrize('name', sorted(TEXT_SCANS))
def test_a_bad_line_far_into_the_file_is_named_by_its_number(tmp_path, name):
    path = tmp_path / name
    header_lines = TEXT_SCANS[name][1]
    _text_scan(path, 20_000)
    lines = path.read_text().splitlines(keepends=True)
    lines[header_lines + 15_000] = lines[header_lines + 15_000].replace('1.000', '1.x00', 1)
    path.write_text(''.join(lines))
    with pytest.raises(ScanFormatError, match=rf'{name}:{header_lines + 15_001}: '):
        read_scan_chunks_joined(path, 512)


def _organised_pcd(path: Path, xyz: np.ndarray, width: int, data: str) -> Path:
    """A depth camera's frame as PCL saves it: WIDTH x HEIGHT records, one per pixel."""
    header = (f'VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n'
              f'WIDTH {width}\nHEIGHT {len(xyz) // width}\nVIEWPOINT 0 0 0 1 0 0 0\n'
              f'POINTS {len(xyz)}\nDATA {data}\n')
    if data == 'binary':
        body = xyz.astype('<f4').tobytes()
    else:
        body = ''.join(' '.join(f'{v:.6g}' for v in row) + '\n' for row in xyz).encode()
    path.write_bytes(header.encode() + body)
    return path


@pytest.mark.parametrize('data', ['binary', 'ascii'])
def test_pixels_without_depth_of_an_organised_pcd_are_left_out(tmp_path, data):
    rng = np.random.default_rng(7)
    xyz = rng.uniform(-2.0, 4.0, (240, 3)).astype(np.float32)
    no_depth = rng.random(240) < 0.3
    xyz[no_depth] = np.nan
    path = _organised_pcd(tmp_path / f'frame_{data}.pcd', xyz, width=20, data=data)
    notes: list[str] = []
    points = np.concatenate(list(read_scan_chunks(path, chunk_points=50, notes=notes)))
    np.testing.assert_allclose(points[:, :3], xyz[~no_depth], rtol=1e-5)
    assert any(f'{int(no_depth.sum())} of 240 records have no coordinates' in note
               for note in notes)


def test_a_pcd_point_with_one_nan_coordinate_is_still_an_error(tmp_path):
    xyz = np.ones((40, 3), np.float32)
    xyz[5, 1] = np.nan
    path = _organised_pcd(tmp_path / 'bad.pcd', xyz, width=8, data='binary')
    with pytest.raises(ScanFormatError, match='non-finite coordinate'):
        read_scan(path)
    all_nan = _organised_pcd(tmp_path / 'empty.pcd', np.full((40, 3), np.nan, np.float32),
                             width=8, data='binary')
    with pytest.raises(ScanFormatError, match='holds no points'):
        read_scan(all_nan)
