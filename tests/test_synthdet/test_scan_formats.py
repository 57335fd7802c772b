"""Scan formats (package synthdet.scan_io): every reader, chunked and bounded reading, errors."""
import math

import numpy as np
import pytest

from configurator.corners import corners_for_scan
from synthdet import scan_io
from synthdet.scan_io import (ScanFormatError, load_scan, read_scan, read_scan_chunks,
                              write_e57_scans, write_las_chunks, write_scan)
from tests.room_scans import NoiseModel, make_room

GEO = np.array([500000.0, 5400000.0, 300.0])  # a georeferenced (UTM-like) offset
FORMATS = ('.e57', '.las', '.laz', '.ply', '.pcd', '.xyz', '.txt')


@pytest.fixture(scope='module')
def room():
    return make_room('L', n_points=120_000, seed=3, noise=NoiseModel())


@pytest.fixture(scope='module')
def geo_points(room):
    points = room.points.copy()
    points[:, :3] += GEO
    return points


def matched(found: np.ndarray, expected: np.ndarray) -> float:
    """Largest distance between corresponding corners (same count, same clockwise start)."""
    assert found.shape == expected.shape, (found, expected)
    return float(np.abs(found - expected).max())


@pytest.mark.parametrize('suffix', FORMATS)
def test_every_format_reads_back_the_same_points_whole_and_in_chunks(tmp_path, geo_points, suffix):
    path = tmp_path / f'room{suffix}'
    write_scan(path, geo_points)
    points = read_scan(path)
    assert points.dtype == np.float64 and points.shape == geo_points.shape
    assert np.abs(points[:, :3] - geo_points[:, :3]).max() <= 0.0005 + 1e-9  # LAS: millimetres
    np.testing.assert_array_equal(points[:, 3:], geo_points[:, 3:])
    notes = []
    chunks = list(read_scan_chunks(path, chunk_points=7_777, notes=notes))
    assert max(len(chunk) for chunk in chunks) <= 7_777 and len(chunks) >= 2
    np.testing.assert_array_equal(np.concatenate(chunks), points)
    assert notes == []  # colors present: nothing to say


def test_float32_bin_keeps_a_local_room_and_warns_for_georeferenced_ones(
        tmp_path, room, geo_points):
    path = tmp_path / 'room.bin'
    write_scan(path, room.points)
    notes = []
    points = np.concatenate(list(read_scan_chunks(path, notes=notes)))
    assert np.abs(points[:, :3] - room.points[:, :3]).max() < 1e-5 and notes == []
    write_scan(path, geo_points)
    list(read_scan_chunks(path, notes=notes))
    assert len(notes) == 1 and 'only exact to 500 mm' in notes[0]
    assert notes[0].startswith(f'{path}: warning: float32 coordinates as large as 5,400,')


def test_every_format_gives_the_same_corners_and_a_shifted_copy_shifted_corners(
        tmp_path, room, geo_points):
    write_scan(tmp_path / 'local.pcd', room.points)
    local = corners_for_scan(tmp_path / 'local.pcd')
    reference = np.array(local['corners'])
    truth = room.polygon
    start = int(np.argmin(np.linalg.norm(truth - truth.min(axis=0), axis=1)))
    assert matched(reference, np.roll(truth, -start, axis=0)) < 0.03
    for suffix in FORMATS:
        path = tmp_path / f'geo{suffix}'
        write_scan(path, geo_points)
        result = corners_for_scan(path)
        corners = np.array(result['corners'])
        # shifted by exactly the offset: to the JSON's 0.1 mm, and LAS stores millimetres
        assert matched(corners - GEO[:2], reference) <= (0.0021 if 'la' in suffix else 0.0002)
        assert abs(result['floor_z'] - GEO[2] - local['floor_z']) <= 0.0021
        assert abs(result['ceiling_z'] - GEO[2] - local['ceiling_z']) <= 0.0021


def test_e57_reads_every_scan_moved_by_its_pose(tmp_path, room):
    points = room.points[:20_000].copy()
    points[:, :3] += GEO
    half = len(points) // 2
    scans = []
    for part, yaw, station in ((points[:half], 0.7, GEO + (3, 1, 1.5)), (points[half:], -2.1,
                                                                         GEO + (-2, 4, 1.2))):
        c, s = math.cos(yaw), math.sin(yaw)
        rotation = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        own = part.copy()
        own[:, :3] = (part[:, :3] - station) @ rotation  # the scanner's own frame
        scans.append((own, rotation, station))
    write_e57_scans(tmp_path / 'two.e57', scans)
    loaded = read_scan(tmp_path / 'two.e57')
    assert np.abs(loaded[:, :3] - points[:, :3]).max() < 1e-4
    np.testing.assert_array_equal(loaded[:, 3:], points[:, 3:])


def test_e57_without_colors_gets_intensity_as_grey(tmp_path):
    import pye57
    xyz = np.random.default_rng(0).uniform(0, 5, (100, 3))
    e57 = pye57.E57(str(tmp_path / 'grey.e57'), mode='w')
    e57.write_scan_raw({
        'cartesianX': xyz[:, 0],
        'cartesianY': xyz[:, 1],
        'cartesianZ': xyz[:, 2],
        'intensity': np.linspace(0, 1, 100)
    })
    e57.close()
    notes = []
    points = np.concatenate(list(read_scan_chunks(tmp_path / 'grey.e57', notes=notes)))
    np.testing.assert_allclose(points[:, 3], np.linspace(0, 255, 100), atol=1e-4)
    np.testing.assert_array_equal(points[:, 3], points[:, 5])
    assert notes == [
        f'{tmp_path / "grey.e57"}: no colors: the model gets the intensity as '
        f'grey instead'
    ]


def test_las_16_bit_colors_and_intensity_without_colors(tmp_path):
    import laspy
    rng = np.random.default_rng(1)
    xyz = GEO + rng.uniform(0, 10, (50, 3))
    for point_format in (2, 0):
        header = laspy.LasHeader(point_format=point_format, version='1.2')
        header.offsets, header.scales = GEO, [0.001] * 3
        las = laspy.LasData(header)
        las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
        las.intensity = np.full(50, 4095, dtype=np.uint16)  # a 12-bit scanner's maximum
        if point_format == 2:
            las.red = las.green = las.blue = np.full(50, 65535, dtype=np.uint16)
        las.write(tmp_path / f'f{point_format}.las')
        notes = []
        points = np.concatenate(
            list(read_scan_chunks(tmp_path / f'f{point_format}.las', notes=notes)))
        assert np.abs(points[:, :3] - xyz).max() <= 0.0005 + 1e-9
        np.testing.assert_array_equal(points[:, 3:], 255.0)  # 65535 color, 4095 intensity
        assert bool(notes) == (point_format == 0)


@pytest.mark.parametrize(
    'name, text, columns, expected',
    [
        ('comma.csv', 'X,Y,Z,R,G,B\n1.5,2,3,10,20,30\n4,5,6,40,50,60\n', None,
         [[1.5, 2, 3, 10, 20, 30], [4, 5, 6, 40, 50, 60]]),
        ('semicolon.csv', '1;2;3\n4;5;6\n', None, [[1, 2, 3, 0, 0, 0], [4, 5, 6, 0, 0, 0]]),
        ('scan.pts', '2\n1 2 3 -2048 10 20 30\n4 5 6 2047 40 50 60\n', None,
         [[1, 2, 3, 10, 20, 30], [4, 5, 6, 40, 50, 60]]),  # x y z intensity r g b
        ('grey.xyz', '1 2 3 0\n4 5 6 255\n', 'x,y,z,i', [[1, 2, 3, 0, 0, 0],
                                                         [4, 5, 6, 255, 255, 255]]),
        ('skip.xyz', '9 1 2 3 10 20 30\n', '_,x,y,z,r,g,b', [[1, 2, 3, 10, 20, 30]]),
        ('tabs.txt', '1\t2\t3\t0.5\n', 'x,y,z,i', [[1, 2, 3, 127.5, 127.5, 127.5]]),
    ])
def test_text_scans_detect_delimiter_header_and_columns(tmp_path, name, text, columns, expected):
    path = tmp_path / name
    path.write_text(text)
    np.testing.assert_allclose(read_scan(path, columns=columns), expected)


def test_pcd_ascii_and_binary_with_packed_colors_and_intensity(tmp_path):
    header = ('VERSION 0.7\nFIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\n'
              'WIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA ascii\n')
    packed = np.array([(10 << 16) | (20 << 8) | 30, (255 << 16)], dtype=np.uint32)
    as_float = packed.view(np.float32)
    (tmp_path / 'a.pcd').write_text(header + f'1 2 3 {as_float[0]!r}\n4 5 6 {as_float[1]!r}\n')
    np.testing.assert_array_equal(
        read_scan(tmp_path / 'a.pcd'), [[1, 2, 3, 10, 20, 30], [4, 5, 6, 255, 0, 0]])
    table = np.array([(1, 2, 3, 0.0), (4, 5, 6, 1.0)],
                     dtype=[('x', '<f4'), ('y', '<f4'), ('z', '<f4'), ('intensity', '<f4')])
    binary = header.replace('rgb', 'intensity').replace('DATA ascii', 'DATA binary')
    (tmp_path / 'b.pcd').write_bytes(binary.encode() + table.tobytes())
    notes = []
    points = np.concatenate(list(read_scan_chunks(tmp_path / 'b.pcd', notes=notes)))
    np.testing.assert_array_equal(points, [[1, 2, 3, 0, 0, 0], [4, 5, 6, 255, 255, 255]])
    assert 'intensity as grey' in notes[0]
    compressed = binary.replace('DATA binary', 'DATA binary_compressed')
    (tmp_path / 'c.pcd').write_bytes(compressed.encode() + b'\0' * 8)
    with pytest.raises(ScanFormatError, match=r'c\.pcd: the header counts 2 points \(32 bytes\) '
                       r'but the binary_compressed data holds 0 bytes'):
        read_scan(tmp_path / 'c.pcd')


def test_clear_one_line_errors_name_the_file(tmp_path, room):
    cases = {
        'scan.obj': (b'v 1 2 3\n', "scan.obj: unknown scan type '.obj', expected one of"),
        'empty.xyz': (b'\n\n', r'empty\.xyz: the scan holds no points'),
        'words.csv': (b'a,b,c\nd,e,f\n', r'words\.csv: no line of 3 or more numbers'),
        'bad.xyz': (b'1 2 3\n4 5 x\n', r'bad\.xyz:2: '),
        'five.xyz': (b'1 2 3 4 5\n', r'five\.xyz:1: 5 values per line; say what they are'),
        'junk.las': (b'LASF but not really', r'junk\.las: not a readable LAS/LAZ file'),
        'junk.e57': (b'\0' * 64, r'junk\.e57: not a readable E57 file'),
        'junk.pcd': (b'hello\n', r'junk\.pcd: not a PCD file'),
    }
    for name, (content, message) in cases.items():
        (tmp_path / name).write_bytes(content)
        with pytest.raises(ScanFormatError, match=message) as error:
            read_scan(tmp_path / name)
        assert '\n' not in str(error.value) and str(tmp_path / name) in str(error.value)
    with pytest.raises(ScanFormatError, match=r"three\.xyz: columns 'x,y' need x, y and z"):
        (tmp_path / 'three.xyz').write_text('1 2 3\n')
        read_scan(tmp_path / 'three.xyz', columns='x,y')
    millimetres = room.points.copy()
    millimetres[:, :3] *= 1000.0
    write_scan(tmp_path / 'mm.laz', millimetres)
    with pytest.raises(
            ScanFormatError,
            match=r'mm\.laz: the scan is [\d,]+ m tall .* the units '
            r'look wrong \(millimetres or centimetres\?\); synthdet expects metres'):
        load_scan(tmp_path / 'mm.laz', voxel=0.05)


def test_files_without_colors_say_what_the_model_gets(tmp_path):
    (tmp_path / 'bare.xyz').write_text('1 2 3\n4 5 6\n')
    loaded = load_scan(tmp_path / 'bare.xyz')
    assert loaded.report[0] == (f'{tmp_path / "bare.xyz"}: no colors and no intensity: the '
                                f'model gets zeros (black) instead')
    np.testing.assert_array_equal(loaded.points[:, 3:], 0.0)


def test_load_scan_voxel_filter_is_chunk_size_independent_and_local(tmp_path, geo_points):
    path = tmp_path / 'room.laz'
    write_scan(path, geo_points)
    whole = load_scan(path, voxel=0.05)
    chunked = load_scan(path, voxel=0.05, chunk_points=3_001)
    np.testing.assert_array_equal(whole.points, chunked.points)
    np.testing.assert_array_equal(whole.origin, chunked.origin)
    assert whole.points_read == len(geo_points) and len(whole.points) < len(geo_points) / 2
    assert np.all(whole.origin == np.floor(whole.origin)) and np.abs(
        whole.points[:, :3]).max() < 50
    scan_xyz = whole.points[:, :3] + whole.origin
    voxels = np.floor(scan_xyz / 0.05).astype(np.int64)
    assert len(np.unique(voxels, axis=0)) == len(voxels)  # one point per voxel
    every = np.unique(np.floor(read_scan(path)[:, :3] / 0.05).astype(np.int64), axis=0)
    assert len(every) == len(voxels)  # and every occupied voxel kept
    assert 'kept' in whole.report[-1] and str(path) in whole.report[-1]


def test_a_point_kilometres_away_is_kept_exactly_by_the_voxel_filter(tmp_path, room):
    points = np.vstack([room.points[:5000], [[5000.0, -3e6, 40.0, 1, 2, 3]]])
    write_scan(tmp_path / 'far.pcd', points)
    loaded = load_scan(tmp_path / 'far.pcd', voxel=0.05)
    assert np.any(np.all(loaded.points + np.r_[loaded.origin, 0, 0, 0] == points[-1], axis=1))


def test_write_las_chunks_streams_a_large_scan(tmp_path, room):
    count = write_las_chunks(tmp_path / 'big.laz', (room.points[i:i + 10_000] + np.r_[GEO, 0, 0, 0]
                                                    for i in range(0, len(room.points), 10_000)))
    assert count == len(room.points)
    points = read_scan(tmp_path / 'big.laz')
    assert np.abs(points[:, :3] - room.points[:, :3] - GEO).max() <= 0.0005 + 1e-9
    assert set(scan_io.WRITERS) >= {'.las', '.laz', '.e57', '.pcd', '.xyz'}


def test_corners_command_reads_any_format_and_writes_the_scan_frame(tmp_path, room, geo_points,
                                                                    capsys):
    from configurator.__main__ import main
    from synthdet.contracts import read_corners
    write_scan(tmp_path / 'geo.laz', geo_points)
    assert main(['corners', str(tmp_path / 'geo.laz'), '--out', str(tmp_path / 'c.json')]) == 0
    output = capsys.readouterr().out
    assert 'corners: levelling:' in output and 'corners: yaw:' in output
    corners = np.array(read_corners(tmp_path / 'c.json')['corners'])
    assert np.abs(corners - GEO[:2]).max() < 30 and len(corners) == len(room.polygon)
    (tmp_path / 'bad.xyz').write_text('1 2\n')
    assert main(['corners', str(tmp_path / 'bad.xyz'), '--out', str(tmp_path / 'd.json')]) == 2
    assert 'corners: bad scan: ' in capsys.readouterr().err
    assert not (tmp_path / 'd.json').exists()
