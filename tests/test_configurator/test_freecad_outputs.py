"""The ``freecad`` command's outputs and processes, with real freecadcmd: runs writing the same
document never mix, nothing of a run is left behind (temporary files, FreeCAD backups, a
FreeCAD process after ``kill -9``, its work folder), thousands of detections all become
objects, and usage errors are one line with exit code 2."""
import json
import os
import random
import re
import signal
import subprocess
import sys
import textwrap
import time
import zipfile
from pathlib import Path

import pytest

from configurator.__main__ import main as configurator_main

REPO = Path(__file__).resolve().parents[2]
ROOM_SIDE = 6.0
CLASSES = ('table', 'chair', 'sofa', 'bookcase', '3dprinter', 'forklift')


def write_inputs(folder: Path,
                 count: int,
                 seed: int = 0,
                 side: float = ROOM_SIDE,
                 name: str = 'room') -> dict[str, Path]:
    """A scan, ``count`` detections of mixed classes in a square room (one per square metre,
    in random cells, so that none overlap), its corners."""
    rng = random.Random(seed)
    scan = folder / f'{name}.txt'
    scan.write_text('0 0 0 1 2 3\n1 1 1 4 5 6\n', encoding='utf-8')
    columns = int(side)
    cells = rng.sample(range(columns * columns), count)
    detections = [{
        'class': CLASSES[index % len(CLASSES)],
        'score': round(rng.uniform(0.5, 1.0), 3),
        'center': [cell % columns + 0.5, cell // columns + 0.5, 0.4],
        'size': [0.5, 0.4, 0.8],
        'yaw': rng.choice([0.0, 0.4]),
    } for index, cell in enumerate(cells)]
    predictions = folder / f'{name}.pred.json'
    predictions.write_text(
        json.dumps({
            'format': 'synthdet.predictions/1',
            'scan': scan.name,
            'model': 'test',
            'detections': detections
        }),
        encoding='utf-8')
    corners = folder / f'{name}.corners.json'
    corners.write_text(
        json.dumps({
            'format': 'synthdet.corners/1',
            'scan': scan.name,
            'corners': [[0, 0], [0, side], [side, side], [side, 0]],
            'floor_z': 0.0,
            'ceiling_z': 2.8,
            'quality': {}
        }),
        encoding='utf-8')
    return {'scan': scan, 'predictions': predictions, 'corners': corners}


def freecad_command(inputs: dict[str, Path], out: Path, *extra: str) -> list[str]:
    return [
        sys.executable, '-m', 'configurator', 'freecad', '--scan',
        str(inputs['scan']), '--predictions',
        str(inputs['predictions']), '--corners',
        str(inputs['corners']), '--out',
        str(out), *extra
    ]


def run_cli(command: list[str],
            tmp_dir: Path,
            timeout: float = 600) -> subprocess.CompletedProcess:
    env = dict(os.environ, TMPDIR=str(tmp_dir))
    return subprocess.run(
        command, cwd=REPO, env=env, capture_output=True, text=True, timeout=timeout)


def document_parts(path: Path) -> list[str]:
    """Names of the detection parts (``Part::FeaturePython`` objects) an .FCStd holds (read
    from its Document.xml)."""
    return [name for kind, name in document_objects(path) if kind == 'Part::FeaturePython']


def document_objects(path: Path) -> list[tuple[str, str]]:
    """(type, name) of every object an .FCStd holds, in order (read from its Document.xml)."""
    with zipfile.ZipFile(path) as archive:
        xml = archive.read('Document.xml').decode('utf-8')
    return re.findall(r'<Object type="([^"]+)" name="([^"]+)"', xml)


def dead_pid() -> int:
    """The id of a process that has ended."""
    process = subprocess.Popen(['true'])
    process.wait()
    return process.pid


def children_of(pid: int) -> list[int]:
    path = Path(f'/proc/{pid}/task/{pid}/children')
    return [int(child) for child in path.read_text().split()] if path.exists() else []


def alive(pid: int) -> bool:
    try:
        state = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[0]
    except FileNotFoundError:
        return False
    return state != 'Z'


def test_runs_writing_one_document_keep_their_own_temporary_files(tmp_path):
    """Two runs at once on the same --out both succeed and the file is one whole document;
    files of a dead run are cleaned, those of a live run kept, and no backup is left."""
    work = tmp_path / 'tmp'
    work.mkdir()
    out_dir = tmp_path / 'out'
    out_dir.mkdir()
    out = out_dir / 'room.FCStd'
    stale = [
        out_dir / f'.room.partial-{dead_pid()}-0a1b2c3d.FCStd{suffix}'
        for suffix in ('', '1', '.gui')
    ]
    live = out_dir / f'.room.partial-{os.getpid()}-0a1b2c3d.FCStd'
    for path in stale + [live]:
        path.write_bytes(b'left by another run')
    first = write_inputs(tmp_path, 6, seed=1, name='first')
    second = write_inputs(tmp_path, 9, seed=2, name='second')
    env = dict(os.environ, TMPDIR=str(work))
    runs = [
        subprocess.Popen(
            freecad_command(inputs, out),
            cwd=REPO,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True) for inputs in (first, second)
    ]
    outputs = [run.communicate(timeout=600) for run in runs]
    for run, (stdout, stderr) in zip(runs, outputs):
        assert run.returncode == 0, stderr
    reported = {int(stdout.split(': ', 1)[1].split(' objects')[0]) for stdout, _ in outputs}
    assert reported == {6, 9}
    assert len(document_parts(out)) in reported
    with zipfile.ZipFile(out) as archive:
        assert archive.testzip() is None
        assert 'GuiDocument.xml' in archive.namelist()
    assert sorted(path.name for path in out_dir.iterdir()) == sorted([out.name, live.name])
    assert list(work.iterdir()) == []


def test_kill_9_ends_freecad_and_a_later_run_cleans_up(tmp_path):
    """``kill -9`` of the command ends freecadcmd at once (no document written later); the
    work folder it could not remove is removed by the next run."""
    work = tmp_path / 'tmp'
    work.mkdir()
    inputs = write_inputs(tmp_path, 8000, side=90.0)  # still being built a second in
    out = tmp_path / 'killed.FCStd'
    env = dict(os.environ, TMPDIR=str(work))
    cli = subprocess.Popen(
        freecad_command(inputs, out),
        cwd=REPO,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while not children_of(cli.pid) and time.monotonic() < deadline:
        time.sleep(0.2)
    freecad = children_of(cli.pid)
    assert freecad, 'freecadcmd did not start'
    time.sleep(1.0)  # FreeCAD is building the document now
    os.kill(cli.pid, signal.SIGKILL)
    assert cli.wait() == -signal.SIGKILL
    deadline = time.monotonic() + 10
    while any(alive(pid) for pid in freecad) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(alive(pid) for pid in freecad)
    left = [path.name for path in work.iterdir()]
    assert len(left) == 1 and left[0].startswith(f'synthdet-freecad-{cli.pid}-')
    time.sleep(3.0)
    assert not out.exists()

    small = write_inputs(tmp_path, 2, name='small')
    done = run_cli(freecad_command(small, tmp_path / 'small.FCStd'), work)
    assert done.returncode == 0, done.stderr
    assert list(work.iterdir()) == []


def test_a_detection_adds_one_object_named_by_synthdet(tmp_path):
    """Each detection is one object, its part, named by synthdet (``Detection001``), and one
    stored shape: no name FreeCAD had to make unique (FreeCAD 0.20 finds a free name by going
    through every name in the document, which made building n detections take time in n
    squared), and one shape file per detection (FreeCAD 0.20 names each shape file by going
    through the names stored before it)."""
    count = 25
    inputs = write_inputs(tmp_path, count)
    detections = json.loads(inputs['predictions'].read_text(encoding='utf-8'))
    for item in detections['detections']:
        item['class'] = 'forklift'
    inputs['predictions'].write_text(json.dumps(detections), encoding='utf-8')
    empty = write_inputs(tmp_path, 0, name='empty')
    outputs = [tmp_path / 'boxes.FCStd', tmp_path / 'empty.FCStd']
    for files, out in zip((inputs, empty), outputs):
        done = run_cli(freecad_command(files, out), tmp_path)
        assert done.returncode == 0, done.stderr
    boxes, room = (document_objects(out) for out in outputs)
    added = [item for item in boxes if item not in room]
    assert len(boxes) == len(room) + count == len(room) + len(added)
    assert sorted(added) == [('Part::FeaturePython', f'Detection{number:03d}')
                             for number in range(1, count + 1)]
    shape_files = []
    for out in outputs:
        with zipfile.ZipFile(out) as archive:
            shape_files.append({name for name in archive.namelist() if name.endswith('.brp')})
    # each part's shape in a file named after it, written by synthdet in linear time
    assert shape_files[0] - shape_files[1] == {
        f'Detection{number:03d}.Shape.brp' for number in range(1, count + 1)}
    # a plain FreeCAD (synthdet's proxy module not loaded) reads every stored shape; loaded
    # afterwards, synthdet gives the parts their proxy back and an edit rebuilds the shape
    script = tmp_path / 'volumes.py'
    report = tmp_path / 'volumes.json'
    script.write_text(textwrap.dedent(f'''\
        import json, sys
        import FreeCAD as App
        doc = App.openDocument({str(outputs[0])!r})
        volumes = {{o.Name: o.Shape.Volume for o in doc.Objects if hasattr(o, 'Shape')}}
        sys.path.insert(0, {str(REPO / 'configurator' / 'freecad')!r})
        from synthdet_freecad import library
        restored = library.restore_proxies(doc)
        doc.Detection001.Length = 1000.0
        doc.recompute()
        json.dump({{'volumes': volumes, 'restored': restored,
                   'edited': doc.Detection001.Shape.Volume}}, open({str(report)!r}, 'w'))
    '''), encoding='utf-8')
    subprocess.run(['freecadcmd', str(script)], cwd=tmp_path, capture_output=True, timeout=120)
    seen = json.loads(report.read_text(encoding='utf-8'))
    assert {name: round(volume) for name, volume in seen['volumes'].items()
            if name.startswith('Detection')} == {
                f'Detection{number:03d}': 500 * 400 * 800 for number in range(1, count + 1)}
    assert seen['volumes']['Walls'] > 0.0
    assert seen['restored'] == count and round(seen['edited']) == 1000 * 400 * 800


def test_a_failing_second_write_of_the_archive_is_one_clear_error(tmp_path):
    """FreeCAD's archive is written once more with the parts' shapes; when that write fails
    (here its temporary name is taken by a folder), the save reports an incomplete document."""
    script = tmp_path / 'save.py'
    report = tmp_path / 'save.json'
    script.write_text(textwrap.dedent(f'''\
        import json, os, sys
        sys.path.insert(0, {str(REPO / 'configurator' / 'freecad')!r})
        sys.path.append({str(REPO)!r})
        import FreeCAD as App
        from synthdet_freecad import archive, editing
        doc = App.newDocument('Blocked')
        editing.add_part(doc, 'table', 1.0, 1.0)
        path = {str(tmp_path / 'blocked.FCStd')!r}
        try:
            archive.save_copy(doc, path, check=lambda saved: os.mkdir(saved + '.shapes'))
            error = None
        except OSError as failure:
            error = str(failure)
        json.dump({{'error': error}}, open({str(report)!r}, 'w'))
    '''), encoding='utf-8')
    subprocess.run(['freecadcmd', str(script)], cwd=tmp_path, capture_output=True, timeout=120)
    error = json.loads(report.read_text(encoding='utf-8'))['error']
    assert error.startswith('FreeCAD could not write a complete document to') and \
        'blocked.FCStd' in error


@pytest.mark.slow
def test_two_thousand_detections_all_become_objects(tmp_path):
    """No quadratic step left on synthdet's side: 2,000 detections, each one part."""
    inputs = write_inputs(tmp_path, 2000, side=45.0)
    out = tmp_path / 'many.FCStd'
    done = run_cli(freecad_command(inputs, out), tmp_path)
    assert done.returncode == 0, done.stderr
    assert ': 2000 objects' in done.stdout
    parts = document_parts(out)
    assert len(parts) == 2000
    assert len(set(parts)) == 2000


@pytest.mark.parametrize('option, value, message', [
    ('--timeout', '-5', 'argument --timeout: expected a number in (0, 604800], got -5'),
    ('--timeout', 'nan', 'argument --timeout: expected a number in (0, 604800], got nan'),
    ('--wall-thickness', 'inf', 'argument --wall-thickness: expected a number in (0, 2], got inf'),
    ('--wall-thickness', '-0.1', 'argument --wall-thickness: expected a number in (0, 2]'),
])
def test_usage_errors_exit_2_with_one_line(tmp_path, capsys, option, value, message):
    inputs = write_inputs(tmp_path, 1)
    with pytest.raises(SystemExit) as stop:
        configurator_main(freecad_command(inputs, tmp_path / 'x.FCStd', option, value)[3:])
    error = capsys.readouterr().err
    assert stop.value.code == 2
    assert error.count('\n') == 1 and message in error
    assert not (tmp_path / 'x.FCStd').exists()


def test_screenshot_timeout_is_a_usage_error(tmp_path, capsys):
    document = tmp_path / 'doc.FCStd'
    with zipfile.ZipFile(document, 'w') as archive:
        archive.writestr('Document.xml', '<Document/>')
    with pytest.raises(SystemExit) as stop:
        configurator_main(
            ['screenshot',
             str(document), '--out',
             str(tmp_path / 'a.png'), '--timeout', '-5'])
    error = capsys.readouterr().err
    assert stop.value.code == 2 and error.count('\n') == 1 and '--timeout' in error


def test_no_room_found_names_the_scan(tmp_path, capsys):
    scan = tmp_path / 'flat floor.txt'
    rng = random.Random(0)
    scan.write_text(
        ''.join(f'{rng.uniform(0, 4):.3f} {rng.uniform(0, 4):.3f} 0.0 1 2 3\n'
                for _ in range(500)),
        encoding='utf-8')
    inputs = write_inputs(tmp_path, 1)
    code = configurator_main([
        'freecad', '--scan',
        str(scan), '--predictions',
        str(inputs['predictions']), '--out',
        str(tmp_path / 'x.FCStd')
    ])
    error = capsys.readouterr().err
    assert code == 2
    assert error.count('\n') == 1 and f'{scan}: no room found: ' in error


def test_the_grid_finds_what_a_comparison_with_everything_finds():
    """Overlaps and nearest keys from the arrangement's grid equal those of a full
    comparison, for small, huge and far-apart footprints."""
    from configurator.freecad.synthdet_freecad.arrangement import Grid, grid_for
    rng = random.Random(3)
    boxes = []
    for _ in range(300):
        x, y = rng.choice([(rng.uniform(0, 10), rng.uniform(0, 10)),
                           (rng.uniform(-500, 500), rng.uniform(-500, 500))])
        half = rng.choice([rng.uniform(0.1, 1.0), rng.uniform(50, 400)])
        boxes.append((x - half, y - half, x + half, y + half))
    grid = grid_for(boxes)
    assert isinstance(grid, Grid)
    for key, box in enumerate(boxes):
        grid.add(key, *box)

    def gap(box, x, y):
        return ((max(box[0] - x, 0.0, x - box[2]))**2 + (max(box[1] - y, 0.0, y - box[3]))**2)**0.5

    for _ in range(200):
        x, y = rng.uniform(-600, 600), rng.uniform(-600, 600)
        query = (x, y, x + rng.uniform(0, 3), y + rng.uniform(0, 3))
        touching = {
            key
            for key, box in enumerate(boxes) if box[0] <= query[2] and query[0] <= box[2]
            and box[1] <= query[3] and query[1] <= box[3]
        }
        assert touching <= grid.overlapping(*query)
        distances = [gap(box, x, y) for box in boxes]
        assert sorted(grid.nearest(x, y, lambda key: gap(boxes[key], x, y))) == \
            [key for key, value in enumerate(distances) if value == min(distances)]
