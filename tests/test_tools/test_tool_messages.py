"""The tools' messages for an unlucky user: one line naming the file, the documented exit code,
nothing half-written, no traceback, no library hint and no 300-digit number.

- checkpoints: a text file named ``.pth``, a truncated checkpoint, a missing one and (for
  ``train.py --resume``) an inference checkpoint; a refused checkpoint names what it holds;
- arguments checked before any work: a CONFIG that is not a config, an ``--out`` that is a file,
  an output folder that does not exist, numbers out of their range (``--points 1e20``, a
  300-digit ``--seed``);
- inputs: a deeply nested JSON, a scan whose name is not UTF-8, an annotation that is a broken
  symbolic link.
"""
import json
import os
import re
import subprocess
from pathlib import Path

import pytest
import torch

from synthdet.contracts import SchemaError, read_corners, read_predictions
from tests.checkpoints import initial_checkpoint
from tests.s3dis_fixtures import S3DIS_DIR, write_synthetic_area
from tests.test_repository.test_faults import REPO, TINY, TINY_CLASSES, OpensMarker, assert_clean_error, run

HUGE = str(10**300)


def assert_short_messages(proc: subprocess.CompletedProcess) -> None:
    """No stderr line of the tool (libraries' warnings aside) longer than 300 characters and no
    run of more than 30 digits."""
    for line in proc.stderr.splitlines():
        if re.search(r'\w+Warning: ', line) or line.startswith(' '):
            continue
        assert len(line) <= 300, line[:400]
        assert not re.search(r'\d{31}', line), line[:400]


@pytest.fixture(scope='module')
def files(tmp_path_factory) -> dict:
    """A synthetic room, an untrained inference checkpoint of the tiny config and bad
    checkpoints: a text file, a truncated checkpoint and one that runs code."""
    root = tmp_path_factory.mktemp('tool_messages')
    write_synthetic_area(root / 'raw', area=1, n_rooms=1, seed=5, points_per_object=200)
    from projects.synthdet.datasets.s3dis_converter import convert_s3dis
    convert_s3dis(root / 'raw', root / 'data', areas=[1])  # test.py reads its infos first
    untrained = initial_checkpoint(TINY, root / 'untrained.pth', TINY_CLASSES)
    text = root / 'notes.pth'
    text.write_text('these are my notes, not a checkpoint\n')
    truncated = root / 'truncated.pth'
    truncated.write_bytes(untrained.read_bytes()[:5000])
    evil = root / 'evil.pth'
    torch.save({'state_dict': {}, 'payload': OpensMarker(root / 'MARKER')}, evil)
    return {
        'root': root,
        'scan': root / 'raw' / S3DIS_DIR / 'Area_1' / 'office_1' / 'office_1.txt',
        'untrained': untrained,
        'text': text,
        'truncated': truncated,
        'evil': evil,
    }


def _tool_commands(checkpoint: Path, files: dict, out: Path) -> dict[str, list]:
    return {
        'predict': ['tools/predict.py', TINY, checkpoint, files['scan'], '--out', out / 'pred'],
        'test': ['tools/test.py', TINY, checkpoint, '--work-dir', out / 'test', '--cfg-options',
                 f"test_dataloader.dataset.data_root={files['root'] / 'data'}/"],
        'resume': ['tools/train.py', TINY, '--work-dir', out / 'train', '--resume', checkpoint],
        'publish': ['tools/publish_model.py', checkpoint, out / 'published.pth'],
        'scan2cad': [
            'tools/scan2cad.py', files['scan'], '--config', TINY, '--checkpoint', checkpoint,
            '--out', out / 'room.FCStd'
        ],
    }


def test_checkpoint_loader_messages(files, tmp_path):
    from projects.synthdet.checkpoint import (CheckpointError, check_resumable,
                                              load_checkpoint_file)
    cases = ((load_checkpoint_file, files['text'], 'not a PyTorch checkpoint'),
             (load_checkpoint_file, files['truncated'], 'truncated or damaged'),
             (load_checkpoint_file, tmp_path / 'missing.pth', 'not found'),
             (check_resumable, files['untrained'], 'no training state'))
    for load, path, expected in cases:
        with pytest.raises(CheckpointError) as error:
            load(path)
        message = str(error.value)
        assert message.startswith(f'{path}: ') and expected in message, message
        assert '\n' not in message and len(message) - len(str(path)) < 200, message
    with pytest.raises(CheckpointError) as error:
        load_checkpoint_file(files['evil'])
    message = str(error.value)
    assert re.search(r'holds (builtins|io)\.open\b', message) and 'not loaded' in message
    assert 'documentation' not in message and '\n' not in message


@pytest.mark.slow
@pytest.mark.parametrize('kind', ['text', 'truncated'])
def test_a_file_that_is_not_a_checkpoint_is_one_line_in_every_tool(files, kind, tmp_path):
    checkpoint = files[kind]
    expected = 'not a PyTorch checkpoint' if kind == 'text' else 'truncated or damaged'
    for name, command in _tool_commands(checkpoint, files, tmp_path).items():
        proc = run(*command)
        assert_clean_error(proc, 2, str(checkpoint), expected)
        assert_short_messages(proc)
    assert not list(tmp_path.glob('published*')) and not (tmp_path / 'room.FCStd').exists()


@pytest.mark.slow
def test_resume_needs_a_training_checkpoint_that_exists(files, tmp_path):
    for checkpoint, expected in ((files['untrained'], 'no training state'),
                                 (tmp_path / 'missing.pth', 'not found')):
        proc = run('tools/train.py', TINY, '--work-dir', tmp_path / 'work', '--resume', checkpoint)
        assert_clean_error(proc, 2, str(checkpoint), expected)


def test_publish_model_names_what_a_refused_checkpoint_holds(files, tmp_path):
    proc = run('tools/publish_model.py', files['evil'], tmp_path / 'published.pth')
    assert_clean_error(proc, 2, str(files['evil']), '.open', 'not loaded')
    assert not (files['root'] / 'MARKER').exists()


@pytest.mark.slow
def test_publish_model_checks_its_output_first_and_never_overwrites_its_input(files, tmp_path):
    proc = run('tools/publish_model.py', files['untrained'], tmp_path / 'missing' / 'model.pth')
    assert_clean_error(proc, 2, str(tmp_path / 'missing' / 'model.pth'), 'does not exist')
    (tmp_path / 'folder.pth').mkdir()
    proc = run('tools/publish_model.py', files['untrained'], tmp_path / 'folder.pth')
    assert_clean_error(proc, 2, str(tmp_path / 'folder.pth'), 'is a folder')
    assert [p.name for p in tmp_path.iterdir()] == ['folder.pth']  # no temporary left
    same = tmp_path / 'model.pth'  # publishing a checkpoint under its own name keeps it
    same.write_bytes(files['untrained'].read_bytes())
    proc = run('tools/publish_model.py', same, same)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert same.read_bytes() == files['untrained'].read_bytes()
    assert len(list(tmp_path.glob('model-*.pth'))) == 1


@pytest.mark.slow
def test_arguments_are_checked_before_the_scans_and_the_model(files, tmp_path):
    not_a_dir = tmp_path / 'taken'
    not_a_dir.write_text('')
    missing = tmp_path / 'missing.pth'  # never looked at: the arguments fail first
    cases = [
        # no config first: every argument is a scan for the shipped model, checked first
        (['tools/predict.py', files['scan'], missing, files['scan'], '--out', tmp_path / 'o'],
         [str(missing), 'scan file not found']),
        (['tools/predict.py', TINY, missing, files['scan'], '--out', not_a_dir],
         [str(not_a_dir), 'expected a folder']),
        (['tools/test.py', TINY, files['untrained'], '--out', tmp_path],
         [str(tmp_path), 'is a folder']),
        (['tools/test.py', files['text'], files['untrained']],
         [str(files['text']), 'not a config file']),
    ]
    folder = tmp_path / 'room.FCStd'
    folder.mkdir()
    cases += [
        (['tools/scan2cad.py', files['scan'], '--config', files['scan'], '--checkpoint', missing,
          '--out', tmp_path / 'other.FCStd'], [str(files['scan']), 'not a config file']),
        (['tools/scan2cad.py', files['scan'], '--config', TINY, '--checkpoint', missing, '--out',
          folder], [str(folder), 'is a folder']),
    ]
    broken = tmp_path / 'broken.py'
    broken.write_text('model = dict(\n')
    cases.append((['tools/predict.py', broken, missing, files['scan'], '--out', tmp_path / 'o'],
                  [f'{broken}:1', 'not a config file']))
    for command, fragments in cases:
        proc = run(*command)
        assert_clean_error(proc, 2, *fragments)
        assert 'checkpoint' not in proc.stderr
    assert not (tmp_path / 'o').exists()


def test_detection_options_out_of_range_are_usage_errors_with_short_messages(capsys):
    import argparse

    from projects.synthdet.bootstrap import add_detection_arguments
    parser = argparse.ArgumentParser(prog='predict.py')
    add_detection_arguments(parser, voxel=None)
    assert parser.parse_args(['--seed', '7', '--voxel', '0.02']).seed == 7
    for option, value in (('--seed', HUGE), ('--seed', '-1'), ('--score-thr', 'nan'),
                          ('--score-thr', '2'), ('--voxel', '-1'), ('--voxel', HUGE)):
        with pytest.raises(SystemExit) as stop:
            parser.parse_args([option, value])
        assert stop.value.code == 2
        message = capsys.readouterr().err.splitlines()[-1]
        assert message.startswith(f'predict.py: error: argument {option}: expected'), message
        assert len(message) < 120 and not re.search(r'\d{31}', message), message


@pytest.mark.slow
def test_predict_rejects_a_huge_seed_before_any_work(files, tmp_path):
    proc = run('tools/predict.py', TINY, files['untrained'], files['scan'], '--out',
               tmp_path / 'pred', '--seed', HUGE)
    assert_clean_error(proc, 2, 'error', '--seed')
    assert_short_messages(proc)
    assert not (tmp_path / 'pred').exists()


def test_generator_numbers_out_of_range_are_usage_errors_with_short_messages(tmp_path):
    for option, value in (('--points', '1e20'), ('--points', HUGE), ('--areas', HUGE),
                          ('--seed', f'-{HUGE}'), ('--shard', f'1/{HUGE}')):
        proc = run('-m', 'generator', '--out', tmp_path / 'rooms', option, value, timeout=120)
        assert_clean_error(proc, 2, 'error', option)
        assert_short_messages(proc)
    for name, config in (('doors', {'room': {'doors': [1, 10**300]}}),
                         ('width', {'room': {'width': [4.0, 1e300]}}),
                         ('noise', {'scanner': {'range_noise': 10**400}})):
        path = tmp_path / f'{name}.json'
        path.write_text(json.dumps(config))
        proc = run('-m', 'generator', '--out', tmp_path / 'rooms', '--config', path, timeout=120)
        assert_clean_error(proc, 2, str(path), name)
        assert_short_messages(proc)
    assert not (tmp_path / 'rooms').exists()
    proc = run('-m', 'generator', '--help', timeout=120)
    assert '1 to 100,000,000' in proc.stdout  # the documented range of --points


def test_deeply_nested_json_is_one_line(tmp_path):
    for reader in (read_predictions, read_corners):
        nested = tmp_path / 'nested.json'
        nested.write_text('[' * 100_000 + ']' * 100_000)
        with pytest.raises(SchemaError, match=f'^{re.escape(str(nested))}: .*nested too deep'):
            reader(nested)


def test_huge_numbers_in_json_are_one_short_line(tmp_path):
    detection = '{"class": "chair", "score": %s, "center": [0, 0, 0], "size": [1, 1, 1]}'
    document = ('{"format": "synthdet.predictions/1", "scan": "s", "model": "m", "classes": [], '
                '"detections": [%s]}')
    for digits, expected in ((400, 'detections[0].score: expected a finite number'),
                             (5000, 'invalid JSON: a number with too many digits')):
        path = tmp_path / f'{digits}.pred.json'
        path.write_text(document % (detection % ('9' * digits)))
        with pytest.raises(SchemaError) as error:
            read_predictions(path)
        message = str(error.value)
        assert message.startswith(f'{path}: ') and expected in message, message
        assert len(message) - len(str(path)) < 120 and 'sys.' not in message, message


def test_json_writers_turn_a_file_name_that_is_not_utf8_into_valid_text(tmp_path):
    from synthdet.contracts import PREDICTIONS_FORMAT, write_predictions
    name = os.fsdecode(b'/scans/hall_\xff.ply')
    out = tmp_path / 'hall.pred.json'
    write_predictions(out, {'format': PREDICTIONS_FORMAT, 'scan': name, 'model': 'm',
                            'classes': [], 'detections': []})
    assert read_predictions(out)['scan'] == '/scans/hall_\N{REPLACEMENT CHARACTER}.ply'
    assert os.listdir(tmp_path) == ['hall.pred.json']


def test_predict_keeps_a_scan_name_that_is_not_utf8(files, tmp_path):
    name = os.fsdecode(b'hall_\xff')  # Latin-1 "y with diaeresis": not UTF-8
    scan = tmp_path / f'{name}.txt'
    scan.write_bytes(files['scan'].read_bytes())
    out = tmp_path / 'out'
    proc = run('tools/predict.py', TINY, files['untrained'], scan, '--out', out, '--score-thr',
               '0.99')
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert 'Traceback' not in proc.stderr
    assert os.listdir(os.fsencode(out)) == [b'hall_\xff.pred.json']  # no temporary left
    document = json.loads((out / f'{name}.pred.json').read_bytes().decode('utf-8'))
    assert document['scan'].endswith('hall_\N{REPLACEMENT CHARACTER}.txt')


def test_an_annotation_that_is_a_broken_link_is_an_error(tmp_path):
    raw = tmp_path / 'raw'
    write_synthetic_area(raw, area=1, n_rooms=1, seed=4, points_per_object=200)
    chair = raw / S3DIS_DIR / 'Area_1' / 'office_1' / 'Annotations' / 'chair_1.txt'
    chair.unlink()
    chair.symlink_to(tmp_path / 'moved_away.txt')
    proc = run(REPO / 'tools' / 'create_data.py', 's3dis', '--root-path', raw, '--out-dir',
               tmp_path / 'out')
    assert_clean_error(proc, 2, str(chair), 'broken symbolic link')


def test_corners_checks_its_outputs_before_the_scan_is_read(tmp_path):
    from synthdet.scan_io import write_scan
    from tests.room_scans import make_room
    scan = tmp_path / 'room.txt'
    write_scan(scan, make_room('rect', 20_000, seed=3).points)
    preview = tmp_path / 'missing' / 'room.png'
    proc = run('-m', 'configurator', 'corners', scan, '--out', tmp_path / 'room.json',
               '--preview', preview)
    assert_clean_error(proc, 1, 'cannot write', str(preview))
    assert 'read' not in proc.stdout  # the scan was not read
    assert sorted(p.name for p in tmp_path.iterdir()) == ['room.txt']  # no JSON without preview
