"""Every command line refuses bad options and inputs before any work, with one line on stderr.

Each case runs the real CLI in a subprocess on small files made here and checks the exit code
(2 bad input or usage, 1 an output that cannot be written) and that stderr is exactly one line
naming the option or the file (docs/safety.md):

- argparse errors of every CLI (``python -m generator``, ``generator.assets``, ``configurator``
  and its sub-commands, every ``tools/*.py`` and ``benchmarks/bench_*.py``): one line, no
  usage block;
- option values: NaN, infinite, negative or huge thresholds, tolerances, timeouts, areas,
  thread and worker counts, ``--cfg-options`` that are not ``key=value``, a ``--launcher``
  outside its launcher, ``--device`` this machine lacks;
- config values: ``model = 5``, a NaN voxel size, a zero floor area, a pipeline that is a
  number; checkpoints whose classes are a string, too few or absurdly long;
- input files: a scan that is a folder, a FIFO or a link to /dev/zero, a text scan with a NaN
  colour or a ragged line, a non-UTF-8 generator config, info pickles without categories, the
  bad inputs of ``tools/count_table.py``;
- bounded work: a YAML config of nested aliases, a corners file of 10,000 corners and a
  1,000-corner one (refused in linear time; a valid one built in seconds), a scan 1e15 m from
  the origin (a warning) and a stray point at 1e300 m.
"""
from __future__ import annotations

import json
import os
import pickle
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from synthdet.scan_io import write_scan
from tests.room_scans import make_room
from tests.tool_process import special_files

REPO = Path(__file__).resolve().parents[2]
TINY = REPO / 'configs' / 'tr3d' / 'tiny.py'
TOOLS = sorted(path.name for path in (REPO / 'tools').glob('*.py'))
# what torchrun, Slurm and MPI set: a run started by hand has none of them
LAUNCH_VARIABLES = ('RANK', 'WORLD_SIZE', 'MASTER_ADDR', 'MASTER_PORT', 'SLURM_PROCID',
                    'OMPI_COMM_WORLD_RANK')


def cli(*args: object, timeout: float = 600,
        library_warnings: bool = True) -> tuple[subprocess.CompletedProcess, float]:
    """Run ``python ARGS...`` from the repository root (one OpenMP thread, no launcher
    variables); returns the process and its wall time in seconds. Without
    ``library_warnings`` Python's warnings are off: the import-time notes of mmengine,
    MinkowskiEngine and mmdet3d on a CPU machine are theirs, not the tool's message."""
    env = {key: value for key, value in os.environ.items() if key not in LAUNCH_VARIABLES}
    env['OMP_NUM_THREADS'] = '1'
    if not library_warnings:
        env['PYTHONWARNINGS'] = 'ignore'
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, *map(str, args)], cwd=REPO, capture_output=True,
                          text=True, timeout=timeout, env=env)
    return proc, time.perf_counter() - start


def one_line_error(proc: subprocess.CompletedProcess, code: int, *fragments: object) -> str:
    """Assert exit ``code`` and exactly one stderr line holding every fragment; return it."""
    lines = proc.stderr.splitlines()
    assert proc.returncode == code, proc.stderr[-3000:]
    assert len(lines) == 1, proc.stderr[-3000:]
    for fragment in map(str, fragments):
        assert fragment in lines[0], lines[0]
    return lines[0]


@pytest.fixture(scope='module')
def inputs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Small valid inputs the bad options are combined with."""
    folder = tmp_path_factory.mktemp('inputs')
    room = make_room(n_points=20_000, seed=3, furniture=0)
    scan = folder / 'room.xyz'
    write_scan(scan, room.points)
    predictions = folder / 'room.pred.json'
    predictions.write_text(json.dumps({'format': 'synthdet.predictions/1', 'detections': []}))
    document = folder / 'room.FCStd'
    document.write_bytes(b'PK\x05\x06' + bytes(18))  # an empty zip: never opened here
    return {'folder': folder, 'scan': scan, 'predictions': predictions, 'document': document,
            'room': room}


# --------------------------------------------------------------------------- argparse errors


@pytest.mark.parametrize('tool', TOOLS)
def test_every_tool_reports_a_usage_error_in_one_line(tool):
    proc, _ = cli(f'tools/{tool}', '--no-such-option')
    line = one_line_error(proc, 2, f'{tool}: error: ')
    assert 'usage:' not in proc.stdout + proc.stderr, line


@pytest.mark.parametrize('args, prog', [
    (['-m', 'generator', '--out', 'x', '--no-such-option'], 'python -m generator'),
    (['-m', 'generator'], 'python -m generator'),
    (['-m', 'generator.assets', '--out', 'x', '--instances', '0'], 'python -m generator.assets'),
    (['-m', 'configurator'], 'python -m configurator'),
    (['-m', 'configurator', 'corners'], 'python -m configurator corners'),
    (['-m', 'configurator', 'freecad', '--no-such-option'], 'python -m configurator freecad'),
    (['-m', 'configurator', 'labels', '--scan', 's'], 'python -m configurator labels'),
    (['-m', 'configurator', 'screenshot', 'd'], 'python -m configurator screenshot'),
])
def test_module_clis_report_usage_errors_in_one_line(args, prog):
    proc, _ = cli(*args)
    one_line_error(proc, 2, f'{prog}: error: ')
    assert 'usage:' not in proc.stderr


BENCHMARKS = sorted(path.name for path in (REPO / 'benchmarks').glob('bench_*.py'))


@pytest.mark.parametrize('benchmark', BENCHMARKS)
def test_every_benchmark_reports_a_usage_error_in_one_line(benchmark):
    proc, _ = cli(f'benchmarks/{benchmark}', '--no-such-option', library_warnings=False)
    one_line_error(proc, 2, f'{benchmark}: error: ')


def test_the_usage_block_comes_with_help_only():
    for args in (['-m', 'configurator', 'corners'], ['tools/count_table.py']):
        proc, _ = cli(*args, '--help')
        assert proc.returncode == 0 and proc.stdout.startswith('usage:') and not proc.stderr


# --------------------------------------------------------------------------- option values


def option_cases(inputs: dict[str, Path]) -> list[tuple[list, str]]:
    """(command, the option its one error line names) for bad option values of every CLI."""
    scan, predictions, folder = inputs['scan'], inputs['predictions'], inputs['folder']
    freecad = ['-m', 'configurator', 'freecad', '--scan', scan, '--predictions', predictions,
               '--out', folder / 'x.FCStd']
    labels = ['-m', 'configurator', 'labels', inputs['document'], '--scan', scan, '--out',
              folder / 'labels']
    detect = ['tools/predict.py', TINY, 'missing.pth', scan, '--out', folder / 'pred']
    scan2cad = ['tools/scan2cad.py', scan, '--config', TINY, '--checkpoint', 'missing.pth',
                '--out', folder / 'x.FCStd']
    huge = '99999999999999999999'
    return [
        ([*freecad, '--min-score', 'nan'], '--min-score'),
        ([*freecad, '--timeout', '1e300'], '--timeout'),
        ([*freecad, '--wall-thickness', '1e9'], '--wall-thickness'),
        ([*labels, '--timeout', '1e300'], '--timeout'),
        ([*labels, '--area', huge], '--area'),
        (['-m', 'configurator', 'screenshot', inputs['document'], '--out', folder / 'x.png',
          '--timeout', '1e300'], '--timeout'),
        (['-m', 'configurator', 'corners', scan, '--out', folder / 'c.json', '--voxel', 'nan'],
         '--voxel'),
        ([*scan2cad, '--wall-thickness', '1e9'], '--wall-thickness'),
        ([*scan2cad, '--cfg-options', 'bogus'], '--cfg-options'),
        ([*detect, '--score-thr', '-5'], '--score-thr'),
        ([*detect, '--cfg-options', 'bogus'], '--cfg-options'),
        ([*detect, '--device', 'gpu'], '--device'),
        (['tools/eval_scans.py', TINY, 'missing.pth', scan, '--out', folder / 'e',
          '--cfg-options', 'model.voxel_size'], '--cfg-options'),
        (['tools/train.py', TINY, '--cfg-options', 'bogus'], '--cfg-options'),
        (['tools/train.py', TINY, '--launcher', 'pytorch'], '--launcher pytorch'),
        (['tools/test.py', TINY, 'missing.pth', '--cfg-options', 'bogus'], '--cfg-options'),
        (['tools/test.py', TINY, 'missing.pth', '--launcher', 'pytorch'], '--launcher pytorch'),
        (['tools/test.py', TINY, 'missing.pth', '--score-thr', '-5'], '--score-thr'),
        (['tools/count_params.py', TINY, '--cfg-options', 'bogus'], '--cfg-options'),
        (['tools/count_table.py', predictions, '--score-thr', '-5'], '--score-thr'),
        (['tools/count_table.py', predictions, '--iou-thr', 'nan'], '--iou-thr'),
        (['tools/check_annotations.py', folder, '--tolerance', 'nan'], '--tolerance'),
        (['tools/check_annotations.py', folder, '--max-outside', '-1'], '--max-outside'),
        (['tools/demo.py', '--threads', '-2'], '--threads'),
        (['tools/create_data.py', 's3dis', '--root-path', folder, '--out-dir', folder / 'o',
          '--workers', '0'], '--workers'),
        (['tools/dataset_stats.py', folder, '--areas', huge], '--areas'),
        (['tools/visualize.py', scan, '--out', folder / 'v.png', '--min-score', 'nan'],
         '--min-score'),
        (['-m', 'generator', '--out', folder / 'rooms', '--object-ratio', 'nan'],
         '--object-ratio'),
    ]


def test_bad_option_values_are_refused_before_any_work(inputs):
    """One line naming the option, exit 2, and nothing written."""
    before = sorted(inputs['folder'].rglob('*'))
    for command, option in option_cases(inputs):
        proc, _ = cli(*command)
        one_line_error(proc, 2, 'error', option)
    assert sorted(inputs['folder'].rglob('*')) == before


def write_light_config(path: Path, model: str = "dict(type='TR3D', voxel_size=0.01)") -> Path:
    """A config without custom imports, enough for predict to check its values."""
    path.write_text(f'model = {model}\n'
                    'inference_window = dict(size=8.0, overlap=2.6)\n'
                    'inference_density = dict(floor_area=59.0)\n'
                    "test_dataloader = dict(dataset=dict(pipeline=[dict(type='PointSample', "
                    'num_points=1000)]))\n')
    return path


def test_config_values_are_checked_when_the_config_loads(inputs, tmp_path):
    config = write_light_config(tmp_path / 'light.py')
    only_model = write_light_config(tmp_path / 'five.py', model='5')
    cases = [
        (config, ['inference_density.floor_area=0'], 'inference_density.floor_area'),
        (config, ['model.voxel_size=nan'], 'model.voxel_size'),
        (config, ['test_dataloader.dataset.pipeline=5'], 'test_dataloader.dataset.pipeline'),
        (config, ["test_dataloader.dataset.metainfo.classes=table"], 'metainfo.classes'),
        (only_model, [], 'model: expected a dict(type=...)'),
    ]
    for path, options, key in cases:
        extra = ['--cfg-options', *options] if options else []
        proc, _ = cli('tools/predict.py', path, 'missing.pth', inputs['scan'], '--out',
                      tmp_path / 'pred', *extra)
        one_line_error(proc, 2, path, key)
    assert not (tmp_path / 'pred').exists()


@pytest.mark.slow
def test_checkpoint_classes_and_devices_are_checked_before_detection(inputs, tmp_path):
    from tests.checkpoints import initial_checkpoint
    classes = ['table', 'chair', 'sofa', 'yumi', '3dprinter']
    cases = [
        (initial_checkpoint(TINY, tmp_path / 'one.pth', ['table']), [],
         '1 class names for a model that predicts 5 classes'),
        (initial_checkpoint(TINY, tmp_path / 'text.pth', 'table'), [], 'got \'table\''),
        (initial_checkpoint(TINY, tmp_path / 'long.pth', ['x' * 10_000, *classes[1:]]), [],
         'name longer than'),
        (tmp_path / 'one.pth', ['--device', 'cuda:99'], '--device cuda:99'),
    ]
    for checkpoint, extra, message in cases:
        proc, _ = cli('tools/predict.py', TINY, checkpoint, inputs['scan'], '--out',
                      tmp_path / 'pred', '--voxel', '0.05', *extra, library_warnings=False)
        line = one_line_error(proc, 2, message)
        assert extra or str(checkpoint) in line
        assert not list((tmp_path / 'pred').glob('*.json'))


# --------------------------------------------------------------------------- input files


def test_a_scan_that_is_no_regular_file_says_what_it_is(inputs, tmp_path):
    fifo, zeros, folder = special_files(tmp_path, '.xyz', '/dev/zero')
    for scan, kind in ((folder, 'is a folder'), (fifo, 'is a FIFO'),
                       (zeros, 'is a character device (/dev/zero)')):
        proc, _ = cli('-m', 'configurator', 'corners', scan, '--out', tmp_path / 'c.json')
        one_line_error(proc, 2, scan, kind)
        proc, _ = cli('-m', 'configurator', 'freecad', '--scan', scan, '--predictions',
                      inputs['predictions'], '--out', tmp_path / 'x.FCStd')
        one_line_error(proc, 2, scan, kind)


def test_text_scans_with_nan_or_ragged_lines_name_the_line(tmp_path):
    rows = [f'{i % 7} {i % 5} {i % 3} 10 20 30' for i in range(200)]
    cases = {
        'nan_first.xyz': (['0 0 0 nan 0 0'] + rows, ':1:', "non-finite value 'nan'"),
        'nan_later.xyz': (rows[:99] + ['1 2 3 nan 20 30'] + rows, ':100:', "'nan'"),
        'ragged.xyz': (rows[:79] + ['1 2 3'] + rows, ':80:', 'expected 6 values per line'),
    }
    for name, (lines, where, message) in cases.items():
        scan = tmp_path / name
        scan.write_text('\n'.join(lines) + '\n')
        proc, _ = cli('-m', 'configurator', 'corners', scan, '--out', tmp_path / 'c.json')
        line = one_line_error(proc, 2, f'{scan}{where}', message)
        assert 'usecols' not in line


def test_generator_configs_that_are_not_utf8_or_nest_aliases_are_refused_quickly(tmp_path):
    latin = tmp_path / 'latin.json'
    latin.write_bytes(b'{\n  "room": {\n    "doors": [1, 2]\n  }\n}\n# caf\xe9\n')
    proc, _ = cli('-m', 'generator', '--out', tmp_path / 'rooms', '--config', latin)
    one_line_error(proc, 2, f'{latin}:6', 'not UTF-8')
    laughs = tmp_path / 'laughs.yaml'
    levels = ['a0: &a0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    levels += [f'a{n}: &a{n} [{", ".join([f"*a{n - 1}"] * 9)}]' for n in range(1, 10)]
    laughs.write_text('\n'.join(levels) + '\nroom:\n  doors: *a9\n')
    proc, seconds = cli('-m', 'generator', '--out', tmp_path / 'rooms', '--config', laughs)
    line = one_line_error(proc, 2, f'{laughs}:2', 'aliases')
    assert seconds < 30 and len(line) < 300 and 'lol' not in line
    assert not (tmp_path / 'rooms').exists()


def test_info_pickles_without_categories_are_one_line(tmp_path):
    info = tmp_path / 's3dis_infos_Area_1.pkl'
    sample = {'lidar_points': {'lidar_path': 'Area_1_office_1.bin'},
              'instances': [{'bbox_3d': [0, 0, 0, 1, 1, 1], 'bbox_label_3d': 0}]}
    info.write_bytes(pickle.dumps({'metainfo': {}, 'data_list': [sample]}))
    proc, _ = cli('tools/dataset_stats.py', tmp_path)
    one_line_error(proc, 2, info, 'categories')


def test_count_table_refuses_each_bad_input_in_one_line(inputs, tmp_path):
    empty = tmp_path / 'empty'
    empty.mkdir()
    broken = tmp_path / 'broken.pred.json'
    broken.write_text('{"format": "synthdet.predictions/1", "detections": [')
    elsewhere = tmp_path / 'elsewhere.pred.json'
    elsewhere.write_text(json.dumps({'format': 'synthdet.predictions/1', 'scan': 'nowhere.txt',
                                     'detections': []}))
    no_paths = tmp_path / 'no_paths.pkl'
    no_paths.write_bytes(pickle.dumps({'metainfo': {'categories': {'table': 0}},
                                       'data_list': [{'instances': []}]}))
    cases = [
        ([tmp_path / 'missing.pred.json'], 'missing.pred.json: predictions file not found'),
        ([empty], f'{empty}: no *.pred.json files'),
        ([broken], f'{broken}:1'),
        ([elsewhere], 'no ground truth for scan nowhere.txt'),
        ([elsewhere, '--infos', tmp_path / 'missing.pkl'], 'missing.pkl: info pickle not found'),
        ([elsewhere, '--infos', no_paths], f'{no_paths}: data_list[0]: no "lidar_points"'),
    ]
    for args, message in cases:
        proc, _ = cli('tools/count_table.py', *args)
        one_line_error(proc, 2, 'count_table.py: error:', message)


def test_an_output_folder_that_cannot_be_written_is_exit_1(inputs):
    unwritable = Path('/sys/synthdet-output')  # sysfs refuses new files, also to root
    proc, _ = cli('tools/predict.py', TINY, 'missing.pth', inputs['scan'], '--out', unwritable)
    one_line_error(proc, 1, unwritable, 'cannot write')
    proc, _ = cli('tools/publish_model.py', 'missing.pth', unwritable / 'model.pth')
    one_line_error(proc, 2, 'does not exist')
    proc, _ = cli('tools/publish_model.py', 'missing.pth', '/sys/model.pth')
    one_line_error(proc, 1, '/sys/model.pth', 'cannot write')


def test_the_test_tool_names_the_show_dir_it_cannot_use(tmp_path):
    """A file given as ``--show-dir`` is bad input naming that option; a folder that cannot be
    written is exit 1 (both before the checkpoint is read)."""
    picture = tmp_path / 'show.png'
    picture.write_bytes(b'not a folder')
    proc, _ = cli('tools/test.py', TINY, 'missing.pth', '--show-dir', picture,
                  library_warnings=False)
    one_line_error(proc, 2, f'--show-dir {picture}: is a file, expected a folder')
    unwritable = Path('/sys/synthdet-show')
    proc, _ = cli('tools/test.py', TINY, 'missing.pth', '--show-dir', unwritable,
                  library_warnings=False)
    one_line_error(proc, 1, unwritable, 'cannot write')


# --------------------------------------------------------------------------- bounded work


def polygon_corners(count: int, clockwise: bool) -> list[list[float]]:
    """``count`` corners of a regular polygon (a circle of radius 10 m), a simple one."""
    angles = np.linspace(0.0, 2 * np.pi, count, endpoint=False)
    angles = -angles if clockwise else angles
    return np.column_stack([10 * np.cos(angles), 10 * np.sin(angles)]).round(6).tolist()


def test_corners_files_with_many_corners_are_checked_in_linear_time(inputs, tmp_path):
    for count, clockwise, message in ((10_000, True, 'expected a list of 3 to 1000'),
                                      (1_000, False, 'counter-clockwise')):
        corners = tmp_path / f'corners_{count}.json'
        corners.write_text(json.dumps({
            'format': 'synthdet.corners/1', 'scan': 'room.xyz', 'floor_z': 0.0,
            'ceiling_z': 3.0, 'quality': {}, 'corners': polygon_corners(count, clockwise)}))
        proc, seconds = cli('-m', 'configurator', 'freecad', '--scan', inputs['scan'],
                            '--predictions', inputs['predictions'], '--corners', corners,
                            '--out', tmp_path / 'x.FCStd', timeout=120)
        one_line_error(proc, 2, corners, message)
        assert seconds < 30, seconds
    assert not (tmp_path / 'x.FCStd').exists()


def test_a_room_of_a_thousand_corners_is_built_in_seconds(inputs, tmp_path):
    """The largest corners file accepted becomes a document with every corner in its floor
    sketch (the sketch is solved once, not once per corner)."""
    import zipfile
    corners = tmp_path / 'round.corners.json'
    corners.write_text(json.dumps({
        'format': 'synthdet.corners/1', 'scan': 'room.xyz', 'floor_z': 0.0, 'ceiling_z': 3.0,
        'quality': {}, 'corners': polygon_corners(1_000, clockwise=True)}))
    out = tmp_path / 'round.FCStd'
    proc, seconds = cli('-m', 'configurator', 'freecad', '--scan', inputs['scan'],
                        '--predictions', inputs['predictions'], '--corners', corners, '--out',
                        out, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert seconds < 60, seconds
    document = zipfile.ZipFile(out).read('Document.xml').decode()
    assert document.count('<Constrain ') == 1_000


def test_far_coordinates_warn_and_a_stray_point_at_1e300_costs_no_overflow(inputs, tmp_path):
    points = inputs['room'].points
    far = tmp_path / 'far.xyz'
    write_scan(far, points + [1e15, 1e15, 0.0, 0.0, 0.0, 0.0])
    proc, _ = cli('-m', 'configurator', 'corners', far, '--out', tmp_path / 'far.json')
    assert proc.returncode in (0, 2), proc.stderr[-3000:]
    assert f'{far}: coordinates 1e+15 m from the origin are too far' in proc.stderr
    stray = tmp_path / 'stray.xyz'
    write_scan(stray, np.vstack([points, [1e300, 1e300, 1.0, 0.0, 0.0, 0.0]]))
    proc, _ = cli('-W', 'error::RuntimeWarning', '-m', 'configurator', 'corners', stray,
                  '--out', tmp_path / 'stray.json')
    assert proc.returncode == 0 and 'Warning' not in proc.stderr, proc.stderr[-3000:]
    assert json.loads((tmp_path / 'stray.json').read_text())['corners']
