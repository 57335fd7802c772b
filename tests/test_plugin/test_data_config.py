"""A JSON or YAML config handed to the tools is data (``projects/synthdet/data_config.py``):
one that would make mmengine import or run code is refused with one line naming the file and
the key, before anything runs; a plain data config (the tiny config dumped as JSON) still loads
and predicts; the project's ``.py`` configs, which are code, keep working.

The hostile configs each name a module or script that writes a marker file when it runs.
"""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from projects.synthdet.bootstrap import load_config
from projects.synthdet.data_config import ConfigFileError, check_data_config
from tests.checkpoints import initial_checkpoint
from synthdet.contracts import write_labels
from tests.s3dis_fixtures import S3DIS_DIR, write_synthetic_area
from tests.test_repository.test_faults import REPO, TINY, TINY_CLASSES, assert_clean_error
from tests.test_synthdet.test_fcstd_guard import refusal as one_line_refusal

MARKER_CODE = "open({marker!r}, 'w').write('ran')\n"


def run_with_path(folder: Path, *args: object) -> subprocess.CompletedProcess:
    """Run ``python ARGS...`` from the repository root with this repository and ``folder``
    (where the hostile modules lie) importable, one OpenMP thread."""
    env = {**os.environ, 'OMP_NUM_THREADS': '1', 'PYTHONPATH': f'{REPO}{os.pathsep}{folder}'}
    return subprocess.run([sys.executable, *map(str, args)], cwd=REPO, capture_output=True,
                          text=True, timeout=900, env=env)


@pytest.fixture(scope='module')
def inputs(tmp_path_factory) -> dict:
    """A synthetic scan, an untrained tiny checkpoint, the tiny config dumped as a data config
    (JSON, without its ``custom_imports``) and modules that write a marker when imported."""
    from mmengine.config import Config
    root = tmp_path_factory.mktemp('data_config')
    write_synthetic_area(root / 'raw', area=1, n_rooms=1, seed=5, points_per_object=200)
    checkpoint = initial_checkpoint(TINY, root / 'untrained.pth', TINY_CLASSES)
    Config.fromfile(TINY).dump(root / 'tiny.json')
    data = json.loads((root / 'tiny.json').read_text(encoding='utf-8'))
    del data['custom_imports']
    (root / 'tiny.json').write_text(json.dumps(data), encoding='utf-8')
    marker = root / 'MARKER'
    for name in ('evil_cfg.py', 'evil_module.py'):
        (root / name).write_text(MARKER_CODE.format(marker=str(marker)), encoding='utf-8')
    (root / 'evil_scope').mkdir()
    (root / 'evil_scope' / 'registry.py').write_text(MARKER_CODE.format(marker=str(marker)))
    return {
        'root': root,
        'data': data,
        'marker': marker,
        'checkpoint': checkpoint,
        'scan': root / 'raw' / S3DIS_DIR / 'Area_1' / 'office_1' / 'office_1.txt',
    }


def write_config(folder: Path, name: str, data: object) -> Path:
    """``data`` as the JSON config ``folder/name``."""
    path = folder / name
    path.write_text(json.dumps(data), encoding='utf-8')
    return path


def refusal(path: Path) -> str:
    """The one-line message, naming ``path`` first, ``check_data_config`` refuses it with."""
    return one_line_refusal(path, check_data_config, ConfigFileError)


def test_a_plain_data_config_loads_and_predicts(inputs, tmp_path):
    config = write_config(tmp_path, 'tiny_data.json', inputs['data'])
    proc = run_with_path(tmp_path, 'tools/predict.py', config, inputs['checkpoint'],
                         inputs['scan'], '--out', tmp_path / 'pred')
    assert proc.returncode == 0, proc.stderr[-3000:]
    predictions = json.loads((tmp_path / 'pred' / 'office_1.pred.json').read_text())
    assert predictions['format'] == 'synthdet.predictions/1'
    # a .py config is code and stays as it was: its custom_imports register the plugin
    assert load_config(TINY).model.type == 'TR3DDetector'


@pytest.mark.slow
def test_the_inference_tools_refuse_a_data_config_that_runs_code(inputs, tmp_path):
    root, marker = inputs['root'], inputs['marker']
    model = dict(inputs['data']['model'], data_preprocessor={
        'type': 'subprocess.getoutput', 'cmd': f'touch {marker}'})
    base = write_config(root, 'base.json', {'_base_': ['./evil_cfg.py']})
    configs = {
        '"_base_" names \'./evil_cfg.py\'': base,
        '"custom_imports" imports Python modules': write_config(
            root, 'imports.json', dict(inputs['data'], custom_imports={
                'imports': ['evil_module']})),
        '"model.data_preprocessor.type" is \'subprocess.getoutput\'': write_config(
            root, 'call.json', dict(inputs['data'], model=model)),
    }
    yaml_config = root / 'apply.yaml'
    yaml_config.write_text(f'model: !!python/object/apply:os.system ["touch {marker}"]\n')
    configs['a YAML tag that builds Python objects (!!python/object/apply:os.system)'] = \
        yaml_config
    scan, checkpoint = inputs['scan'], inputs['checkpoint']
    write_labels(scan.with_name(f'{scan.stem}.labels.json'), {
        'format': 'synthdet.labels/1', 'scan': scan.name, 'classes': TINY_CLASSES, 'boxes': []})
    runs = [(config, expected, ['tools/predict.py', config, checkpoint, scan, '--out',
                                tmp_path / 'pred']) for expected, config in configs.items()]
    runs += [(base, '"_base_" names', command) for command in (
        ['tools/scan2cad.py', scan, '--config', base, '--checkpoint', checkpoint, '--out',
         tmp_path / 'room.FCStd'],
        ['tools/eval_scans.py', base, checkpoint, scan, '--out', tmp_path / 'eval'],
        ['tools/test.py', base, checkpoint, '--work-dir', tmp_path / 'test'],
        ['tools/train.py', base, '--work-dir', tmp_path / 'train'],
        ['tools/count_params.py', base],
        ['tools/adapt.py', scan.parent, '--config', base, '--checkpoint', checkpoint, '--work',
         tmp_path / 'adapt', '--out', tmp_path / 'adapted.pth'])]
    for config, expected, command in runs:
        proc = run_with_path(root, *command)
        assert_clean_error(proc, 2, str(config), expected, 'data only')
        assert not marker.exists(), (command, proc.stderr[-2000:])
    assert not [path.name for path in tmp_path.iterdir()]


def test_bases_class_names_and_scopes(inputs, tmp_path):
    data = {'model': {'type': 'TR3DDetector', 'loss': {'type': 'mmdet.FocalLoss'}},
            'default_scope': 'mmdet3d'}
    check_data_config(write_config(tmp_path, 'plain.json', data))
    # JSON and YAML bases are checked the same way, a cycle of them ends
    inner = write_config(tmp_path, 'inner.json', {'custom_imports': {'imports': ['os']}})
    with pytest.raises(ConfigFileError) as error:
        check_data_config(write_config(tmp_path, 'outer.json', {'_base_': 'inner.json'}))
    assert str(error.value).startswith(f'{inner}: "custom_imports" imports Python modules')
    write_config(tmp_path, 'a.json', {'_base_': ['b.json'], 'x': 1})
    (tmp_path / 'b.yaml').write_text('_base_: [a.json]\ny: &shared {type: TR3DHead}\nz: *shared\n')
    write_config(tmp_path, 'b.json', {'_base_': ['b.yaml']})
    check_data_config(tmp_path / 'a.json')
    cases = {
        'package.json': ({'_base_': ['mmdet3d::_base_/default_runtime.py']},
                         '"_base_" names \'mmdet3d::_base_/default_runtime.py\''),
        'dotted.json': ({'optim_wrapper': {'constructor': 'mmengine.dump'}},
                        '"optim_wrapper.constructor" is \'mmengine.dump\', which no registry'),
        'listed.json': ({'custom_hooks': [{'type': 'os.system'}]},
                        '"custom_hooks[0].type" is \'os.system\''),
        'scope.json': ({'model': {'_scope_': 'evil_scope', 'type': 'TR3DDetector'}},
                       '"model._scope_" is \'evil_scope\', which is no registry scope'),
        'default.json': ({'default_scope': 'evil_scope'}, '"default_scope" is \'evil_scope\''),
    }
    for name, (data, expected) in cases.items():
        message = refusal(write_config(tmp_path, name, data))
        assert expected in message and 'a JSON or YAML config is data only' in message
    broken = tmp_path / 'broken.json'
    broken.write_text('{\n  "model": {,\n}\n')
    assert refusal(broken).startswith(f'{broken}:2: not a JSON config')
    assert not inputs['marker'].exists()
