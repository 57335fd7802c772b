"""The detector that ships with synthdet (projects/synthdet/weights/): the file its model card
describes, loaded as weights only, and a model that finds the objects of a generated room it
never saw with no config or checkpoint named."""
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from projects.synthdet import shipped_model as shipped
from synthdet.contracts import read_room, write_labels
from tests.generator_runs import generate_rooms

REPO = Path(__file__).resolve().parents[2]
DETECTED = ('table', 'chair', 'sofa', 'yumi', '3dprinter')
MAX_BYTES = 32 * 1024 * 1024


def test_the_weights_are_the_file_the_model_card_describes():
    assert shipped.SHIPPED_WEIGHTS.stat().st_size <= MAX_BYTES
    assert shipped.file_sha256(shipped.SHIPPED_WEIGHTS) == shipped.card_sha256()


def test_a_changed_or_missing_file_is_refused_with_its_name(tmp_path, monkeypatch):
    changed = tmp_path / 'tr3d_exp2_cpu.pth'
    data = bytearray(shipped.SHIPPED_WEIGHTS.read_bytes())
    data[-1] ^= 1
    changed.write_bytes(bytes(data))
    monkeypatch.setattr(shipped, 'SHIPPED_WEIGHTS', changed)
    with pytest.raises(shipped.ShippedModelError, match='SHA-256 differs'):
        shipped.shipped_model()
    changed.unlink()
    with pytest.raises(shipped.ShippedModelError, match='missing'):
        shipped.shipped_model()
    card = tmp_path / 'README.md'
    card.write_text('no digest here\n', encoding='utf-8')
    with pytest.raises(shipped.ShippedModelError, match='found 0'):
        shipped.card_sha256(card)


def test_the_weights_load_weights_only_into_the_shipped_config():
    from mmengine.config import Config

    from mmdet3d.registry import MODELS
    from mmdet3d.utils import register_all_modules
    register_all_modules()
    checkpoint = torch.load(shipped.SHIPPED_WEIGHTS, map_location='cpu', weights_only=True)
    assert set(checkpoint) == {'meta', 'state_dict'}
    cfg = Config.fromfile(shipped.SHIPPED_CONFIG)
    model = MODELS.build(cfg.model)
    state = {key: value.float() if value.is_floating_point() else value
             for key, value in checkpoint['state_dict'].items()}
    assert model.load_state_dict(state, strict=True)
    assert tuple(checkpoint['meta']['dataset_meta']['classes']) == DETECTED


def test_model_arguments_are_a_config_and_checkpoint_or_none():
    assert shipped.split_model_arguments(['a.py', 'b.pth', 'scan.ply']) == ('a.py', 'b.pth',
                                                                           ['scan.ply'])
    assert shipped.split_model_arguments(['scan.ply', 'hall.laz']) == (None, None,
                                                                      ['scan.ply', 'hall.laz'])
    config, checkpoint, line = shipped.resolve_model(None, None)
    assert Path(checkpoint) == shipped.SHIPPED_WEIGHTS and 'shipped model' in line
    assert shipped.resolve_model('a.py', 'b.pth')[:2] == ('a.py', 'b.pth')
    with pytest.raises(ValueError, match='both --config and --checkpoint'):
        shipped.resolve_model('a.py', None)


def _labelled_room(work: Path) -> Path:
    """One generated room of fixed seeds (not among the training rooms) as a PLY with its true
    boxes as ``<stem>.labels.json``, the way a user's labelled scan is laid out."""
    generate_rooms(work / 'generated', 1, 1, 200_000, 1000, '--profile', 'mixed_rooms', '--ply')
    room = next((work / 'generated' / 'Area_1').iterdir())
    scans = work / 'scans'
    scans.mkdir()
    shutil.copy(room / f'{room.name}.ply', scans / f'{room.name}.ply')
    boxes = [
        dict(item['box'], **{'class': item['class']})
        for item in read_room(room / 'meta.json')['objects'] if item['class'] in DETECTED
    ]
    write_labels(scans / f'{room.name}.labels.json', {
        'format': 'synthdet.labels/1',
        'scan': f'{room.name}.ply',
        'source': 'generated',
        'frame': 'room',
        'classes': list(DETECTED),
        'boxes': boxes
    })
    return scans


def test_with_no_model_named_the_shipped_one_finds_a_generated_rooms_objects(tmp_path):
    scans = _labelled_room(tmp_path)
    out = tmp_path / 'eval'
    run = subprocess.run([sys.executable, 'tools/eval_scans.py',
                          str(scans), '--out', str(out)],
                         cwd=REPO, capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr[-2000:]
    assert 'model: the shipped model projects/synthdet/weights/tr3d_exp2_cpu.pth' in run.stdout
    result = json.loads((out / 'real_scans.json').read_text())
    assert result['truth'] >= 5
    assert result['overall_recall'] >= 0.9, run.stdout[-2000:]
