"""Fine-tuning from TR3D's published S3DIS checkpoint (configs/tr3d/exp3_finetune.py).

There is no network here to download the real checkpoint, so the test writes one with its
parameter layout, built from the facts of mmdetection3d's ``projects/TR3D`` (names and shapes,
not its code): ``TR3DMinkResNet`` is mmdet3d's ``MinkResNet`` with a BatchNorm stem and planes
(64, 128, 128, 128), i.e. ``conv1``/``norm1`` and ``layer1..4`` of MinkowskiEngine
``BasicBlock``s (``conv1``, ``norm1``, ``conv2``, ``norm2``, and in each stage's first block a
stride-2 ``downsample`` of a 1x1x1 convolution and a BatchNorm); ``TR3DNeck`` drops the first
stage and has ``up_block_1/2`` (generative transposed convolution, BatchNorm, ReLU),
``lateral_block_0/1`` and ``out_block_0/1`` (3x3x3 convolution, BatchNorm, ReLU); ``TR3DHead``
has ``conv_reg`` (6 outputs) and ``conv_cls`` (5 S3DIS classes), 1x1x1 with bias. MinkowskiEngine
0.5.4 (the version mmdetection3d's TR3D runs on) stores a kernel as (kernel volume, in, out),
without the volume axis for a 1x1x1 kernel of stride 1 (the head's, not the strided
``downsample``), and a bias as (1, out); its BatchNorm wraps ``torch.nn.BatchNorm1d`` as ``bn``.
"""
from pathlib import Path

import pytest
import torch
from mmengine.config import Config
from mmengine.registry import init_default_scope
from mmengine.runner import load_checkpoint

REPO = Path(__file__).resolve().parents[2]
PUBLISHED = ('https://download.openmmlab.com/mmdetection3d/v1.1.0_models/tr3d/'
             'tr3d_1xb16_s3dis-3d-5class/tr3d_1xb16_s3dis-3d-5class.pth')
STAGE_BLOCKS, STAGE_PLANES, STEM = (3, 4, 6, 3), (64, 128, 128, 128), 64
NECK_CHANNELS, NUM_CLASSES = 128, 5


def batch_norm(prefix: str, channels: int) -> dict[str, tuple]:
    return {
        **{
            f'{prefix}.bn.{name}': (channels, )
            for name in ('weight', 'bias', 'running_mean', 'running_var')
        }, f'{prefix}.bn.num_batches_tracked': ()
    }


def published_tr3d_s3dis_layout() -> dict[str, tuple]:
    """Parameter and buffer names of TR3D's S3DIS model in mmdetection3d, with shapes."""
    layout = {'backbone.conv1.kernel': (27, 3, STEM), **batch_norm('backbone.norm1', STEM)}
    inplanes = STEM
    for stage, (blocks, planes) in enumerate(zip(STAGE_BLOCKS, STAGE_PLANES), start=1):
        for block in range(blocks):
            prefix = f'backbone.layer{stage}.{block}'
            layout[f'{prefix}.conv1.kernel'] = (27, inplanes if block == 0 else planes, planes)
            layout[f'{prefix}.conv2.kernel'] = (27, planes, planes)
            layout.update(batch_norm(f'{prefix}.norm1', planes))
            layout.update(batch_norm(f'{prefix}.norm2', planes))
            if block == 0:
                layout[f'{prefix}.downsample.0.kernel'] = (1, inplanes, planes)  # stride 2
                layout.update(batch_norm(f'{prefix}.downsample.1', planes))
        inplanes = planes
    for name in ('up_block_1', 'up_block_2', 'lateral_block_0', 'lateral_block_1', 'out_block_0',
                 'out_block_1'):
        layout[f'neck.{name}.0.kernel'] = (27, NECK_CHANNELS, NECK_CHANNELS)
        layout.update(batch_norm(f'neck.{name}.1', NECK_CHANNELS))
    for name, outputs in (('conv_reg', 6), ('conv_cls', NUM_CLASSES)):
        layout[f'bbox_head.{name}.kernel'] = (NECK_CHANNELS, outputs)
        layout[f'bbox_head.{name}.bias'] = (1, outputs)
    return layout


def build_model(config: str) -> torch.nn.Module:
    from mmdet3d.registry import MODELS

    cfg = Config.fromfile(str(REPO / 'configs' / 'tr3d' / config))
    init_default_scope(cfg.default_scope)
    return MODELS.build(cfg.model)


def test_finetune_config_starts_from_the_published_checkpoint() -> None:
    cfg = Config.fromfile(str(REPO / 'configs' / 'tr3d' / 'exp3_finetune.py'))
    exp3 = Config.fromfile(str(REPO / 'configs' / 'tr3d' / 'exp3.py'))
    assert cfg.load_from == PUBLISHED and exp3.get('load_from') is None
    assert not cfg.get('resume', False)
    for key in ('model', 'train_dataloader', 'test_dataloader', 'optim_wrapper', 'train_cfg'):
        assert cfg[key] == exp3[key], key


@pytest.mark.parametrize('config', ['exp3_finetune.py', 'exp1.py'])
def test_a_checkpoint_of_the_published_layout_loads_strictly(config: str, tmp_path: Path) -> None:
    layout = published_tr3d_s3dis_layout()
    generator = torch.Generator().manual_seed(0)
    state = {
        name: (torch.randint(0, 100, shape, generator=generator)
               if name.endswith('tracked') else torch.randn(shape, generator=generator))
        for name, shape in layout.items()
    }
    path = tmp_path / 'tr3d_1xb16_s3dis-3d-5class.pth'
    torch.save(
        {
            'meta': {
                'dataset_meta': {
                    'classes': ['table', 'chair', 'sofa', 'bookcase', 'board']
                }
            },
            'state_dict': state
        }, path)
    model = build_model(config)
    assert {k: tuple(v.shape) for k, v in model.state_dict().items()} == layout
    load_checkpoint(model, str(path), map_location='cpu', strict=True)
    for name, value in model.state_dict().items():
        assert torch.equal(value, state[name]), name
