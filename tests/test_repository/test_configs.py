"""The experiment configs as mmengine resolves them: areas, data roots and pipelines.

The configs derive from ``_base_`` (``projects/synthdet/config_helpers.py``); these are the
values they were written out with before, so a change of the derivation cannot change them.
"""
import copy
from pathlib import Path

import pytest
import torch
from mmengine.config import Config
from mmengine.optim import build_optim_wrapper

from projects.synthdet.config_helpers import (PRE_SAMPLING_STEPS, area_datasets, with_num_points,
                                              with_structure_thinning, with_test_time_augmentation,
                                              with_voxel_grid_sample, without_pre_sampling)
from projects.synthdet.inference.windows import density_from_config

CONFIGS = Path(__file__).resolve().parents[2] / 'configs' / 'tr3d'
AUGMENTATION = ['RandomFlip3D', 'GlobalRotScaleTrans']
TRAIN_STEPS = [
    'LoadPointsFromFile', 'LoadAnnotations3D', 'PointSample', *AUGMENTATION,
    'NormalizePointsColor', 'Pack3DDetInputs'
]
TEST_STEPS = ['LoadPointsFromFile', 'PointSample', 'NormalizePointsColor', 'Pack3DDetInputs']


def with_pre_sampling(steps: list[str], *pre_sampling: str) -> list[str]:
    """The step names with ``pre_sampling`` right before ``PointSample``."""
    index = steps.index('PointSample')
    return steps[:index] + list(pre_sampling) + steps[index:]


def with_robustness_steps(steps: list[str]) -> list[str]:
    """The step names with the base config's robustness augmentations right after PointSample."""
    index = steps.index('PointSample') + 1
    return steps[:index] + ROBUSTNESS + steps[index:]


ROBUSTNESS = [
    'RandomQuarterTurn', 'RandomDensityFalloff', 'RandomPointDropout', 'RandomJitterPoints',
    'RandomColorJitter', 'RandomDropPointsColor'
]
THINNING = ('ThinRoomStructure', )


# config: train areas, test area, data_root, sampled points, train steps, test steps
# (tests/test_tools/test_tr3d_tools.py checks the classes, models and schedules)
EXPECTED = {
    'exp1': ([1, 2, 3, 4, 6], 5, 'data/s3dis/', 100000, TRAIN_STEPS, TEST_STEPS),
    'exp2': ([7, 8], 9, 'data/s3dis/', 100000, TRAIN_STEPS, TEST_STEPS),
    'exp2_paper': ([1, 2, 3, 7, 8], 9, 'data/s3dis/', 100000, TRAIN_STEPS, TEST_STEPS),
    'exp3': ([1, 2, 3, 4, 6, 7, 8, 9], 5, 'data/s3dis/', 100000, TRAIN_STEPS, TEST_STEPS),
    'exp3_finetune': ([1, 2, 3, 4, 6, 7, 8, 9], 5, 'data/s3dis/', 100000, TRAIN_STEPS,
                      TEST_STEPS),
    'exp2_cpu': ([7, 8], 9, 'data/s3dis/', 40000,
                 with_robustness_steps(with_pre_sampling(TRAIN_STEPS, *THINNING)),
                 with_pre_sampling(TEST_STEPS, *THINNING)),
    'tiny': ([1], 1, 'data/s3dis_tiny/', 10000,
             [s for s in TRAIN_STEPS if s not in AUGMENTATION], TEST_STEPS),
}


def load(name: str) -> Config:
    return Config.fromfile(CONFIGS / f'{name}.py', import_custom_modules=False)


def _num_points(pipeline: list) -> list[int]:
    return [step['num_points'] for step in pipeline if step['type'] == 'PointSample']


@pytest.mark.parametrize('name', sorted(EXPECTED))
def test_resolved_datasets_and_pipelines(name):
    areas, test_area, data_root, num_points, train_steps, test_steps = EXPECTED[name]
    cfg = load(name)
    datasets = cfg.train_dataloader.dataset.dataset.datasets
    assert [d.ann_file for d in datasets] == [f's3dis_infos_Area_{a}.pkl' for a in areas]
    for dataset in datasets:
        assert dataset.data_root == data_root and dataset.pipeline == cfg.train_pipeline
        assert dataset.metainfo == cfg.metainfo
    assert [step.type for step in cfg.train_pipeline] == train_steps
    assert _num_points(cfg.train_pipeline) == [num_points]
    assert cfg.val_dataloader == cfg.test_dataloader
    test_set = cfg.test_dataloader.dataset
    assert (test_set.ann_file, test_set.data_root) == (f's3dis_infos_Area_{test_area}.pkl',
                                                       data_root)
    assert test_set.pipeline == cfg.test_pipeline and test_set.metainfo == cfg.metainfo
    assert [step.type for step in cfg.test_pipeline] == test_steps
    assert _num_points(cfg.test_pipeline) == [num_points]


THIN_STRUCTURE = dict(type='ThinRoomStructure', keep=0.1)
PRE_SAMPLING = {  # per config: the steps before PointSample in its train and test pipelines
    'exp2_cpu': {
        'train_pipeline': [dict(THIN_STRUCTURE, cached_rooms=1000)],
        'test_pipeline': [THIN_STRUCTURE]
    },
    'tiny': {
        'train_pipeline': [],
        'test_pipeline': []
    }
}


@pytest.mark.parametrize('name', sorted(PRE_SAMPLING))
def test_cpu_configs_change_only_points_thinning_voxels_levels_and_robustness_of_exp2(name):
    exp2, cfg = load('exp2'), load(name)
    robust = [step for step in cfg.train_pipeline if step.type in ROBUSTNESS]
    assert robust == ([] if name == 'tiny' else list(exp2.robust_augmentations))
    for key in ('train_pipeline', 'test_pipeline'):
        pre_sampling = [step for step in cfg[key] if step.type in PRE_SAMPLING_STEPS]
        assert pre_sampling == PRE_SAMPLING[name][key]
        derived = [
            step for step in cfg[key]
            if step.type not in ('PointSample', *PRE_SAMPLING_STEPS, *ROBUSTNESS)
        ]
        original = [
            step for step in exp2[key]
            if step.type != 'PointSample' and step.type in [s.type for s in cfg[key]]
        ]
        assert derived == original
    changed = dict(exp2.model, voxel_size=0.02)
    if name == 'exp2_cpu':  # the 16 cm head level with the printers, the pruned generated voxels
        changed['neck'] = dict(exp2.model.neck, backbone_fine_level=True, generated_reach=1)
        changed['bbox_head'] = dict(exp2.model.bbox_head, label2level=(2, 1, 1, 1, 0))
    assert exp2.model.voxel_size == 0.01 and cfg.model == changed


def test_helpers_copy_and_refuse_a_pipeline_without_point_sample():
    pipeline = [dict(type='LoadPointsFromFile'), dict(type='PointSample', num_points=5)]
    changed = with_num_points(pipeline, 7)
    assert _num_points(changed) == [7] and _num_points(pipeline) == [5]
    with pytest.raises(ValueError, match='no PointSample step'):
        with_num_points(pipeline[:1], 7)
    thinning = dict(type='ThinRoomStructure', keep=0.2)
    thin = with_structure_thinning(pipeline, thinning)
    assert thin == [pipeline[0], thinning, pipeline[1]] and len(pipeline) == 2
    assert without_pre_sampling(thin) == pipeline
    with pytest.raises(ValueError, match='already thins'):
        with_structure_thinning(thin, thinning)
    grid = dict(type='VoxelGridSample', voxel_size=0.03)
    assert with_voxel_grid_sample(thin, 0.03) == [pipeline[0], grid, thinning, pipeline[1]]
    assert with_voxel_grid_sample(pipeline, 0.03) == [pipeline[0], grid, pipeline[1]]
    assert without_pre_sampling(with_voxel_grid_sample(thin, 0.03)) == pipeline
    with pytest.raises(ValueError, match='already has a voxel grid'):
        with_voxel_grid_sample(with_voxel_grid_sample(pipeline, 0.03), 0.03)
    with pytest.raises(ValueError, match='no PointSample step'):
        with_voxel_grid_sample(pipeline[:1], 0.03)
    with pytest.raises(ValueError, match='no PointSample step'):
        with_structure_thinning(pipeline[:1], thinning)
    template = dict(type='SynthdetS3DISDataset', data_root='d/')
    assert area_datasets(template, [2, 9], dict(classes=('sofa', ))) == [
        dict(template, ann_file=f's3dis_infos_Area_{a}.pkl', metainfo=dict(classes=('sofa', )))
        for a in (2, 9)
    ]


@pytest.mark.parametrize('name', sorted(EXPECTED))
def test_every_tta_version_runs_the_test_pipeline_of_its_config(name):
    cfg = load(name)
    load_step, augment = cfg.tta_pipeline
    test_pipeline = cfg.test_dataloader.dataset.pipeline
    assert load_step == test_pipeline[0] and augment['type'] == 'TestTimeAug'
    flips, *steps = augment['transforms']
    assert [(f['flip_ratio_bev_horizontal'], f['flip_ratio_bev_vertical']) for f in flips] == [
        (0, 0), (0, 1), (1, 0), (1, 1)]
    # two random point samples per flip: eight versions of every scene
    assert steps == [[step] * (2 if step['type'] == 'PointSample' else 1)
                     for step in test_pipeline[1:]]
    assert cfg.tta_model == dict(type='SynthdetTTAModel', fusion_iou_thr=0.5)


def test_tta_pipeline_draws_several_point_samples_per_flip():
    pipeline = [dict(type='LoadPointsFromFile'), dict(type='ThinRoomStructure'),
                dict(type='PointSample', num_points=5), dict(type='Pack3DDetInputs')]
    load_step, augment = with_test_time_augmentation(pipeline, draws=3)
    assert load_step == pipeline[0]
    assert augment['transforms'][1:] == [[pipeline[1]], [pipeline[2]] * 3, [pipeline[3]]]
    with pytest.raises(ValueError, match='at least 1'):
        with_test_time_augmentation(pipeline, draws=0)
    with pytest.raises(ValueError, match='no PointSample step'):
        with_test_time_augmentation(pipeline[:1])


@pytest.mark.parametrize('name', sorted(EXPECTED))
def test_training_density_is_the_sampled_points_over_the_median_floor_area(name):
    cfg = load(name)
    assert cfg.inference_window == dict(size=8.0, overlap=2.6)
    assert cfg.inference_density == dict(floor_area=59.0)
    thinned = 'ThinRoomStructure' in EXPECTED[name][5]  # keep=0.1: 10x the points
    assert density_from_config(cfg) == pytest.approx(EXPECTED[name][3] / 59.0 *
                                                     (10 if thinned else 1))
    with pytest.raises(ValueError, match='no inference_density'):
        density_from_config({key: cfg[key] for key in cfg if key != 'inference_density'})


def test_training_density_counts_the_structure_thinning():
    def config(*steps: dict) -> dict:
        pipeline = [*steps, dict(type='PointSample', num_points=1000)]
        return dict(
            inference_density=dict(floor_area=50.0),
            test_dataloader=dict(dataset=dict(pipeline=pipeline)))

    assert density_from_config(config()) == pytest.approx(20.0)
    assert density_from_config(config(dict(type='ThinRoomStructure', keep=0.25))) == \
        pytest.approx(80.0)
    assert density_from_config(config(dict(type='ThinRoomStructure'))) == pytest.approx(200.0)


@pytest.mark.parametrize('name, train_area, test_area, robust', [
    ('domain_shift_cpu', [11], 21, False),
    ('domain_shift_mixed_cpu', [12], 28, True),
])
def test_domain_shift_configs_are_exp2_at_cpu_scale_by_iterations(name, train_area, test_area,
                                                                  robust):
    exp2, cfg = load('exp2'), load(name)
    assert cfg.robustness is robust
    robust_steps = [step for step in cfg.train_pipeline if step.type in ROBUSTNESS]
    assert robust_steps == (list(exp2.robust_augmentations) if robust else [])
    for key in ('train_pipeline', 'test_pipeline'):  # no thinning: the benchmark's kept models
        derived = [step for step in cfg[key] if step.type not in ROBUSTNESS]
        assert derived == with_num_points(exp2[key], 40000)
    assert cfg.model == dict(exp2.model, voxel_size=0.02,
                             neck=dict(exp2.model.neck, backbone_fine_level=False))
    datasets = cfg.train_dataloader.dataset.dataset.datasets
    assert [d.ann_file for d in datasets] == [f's3dis_infos_Area_{a}.pkl' for a in train_area]
    assert all(d.pipeline == cfg.train_pipeline for d in datasets)
    assert cfg.test_dataloader.dataset.ann_file == f's3dis_infos_Area_{test_area}.pkl'
    assert cfg.test_dataloader.dataset.pipeline == cfg.test_pipeline
    assert cfg.train_dataloader.batch_size == 4 and cfg.train_dataloader.dataset.times == 1
    assert cfg.train_dataloader.sampler.type == 'InfiniteSampler'
    assert cfg.val_dataloader is None and cfg.val_cfg is None
    assert cfg.train_cfg == dict(type='IterBasedTrainLoop', max_iters=cfg.max_iters)
    assert cfg.param_scheduler.milestones == [cfg.max_iters * 4 // 5]
    assert cfg.default_hooks.checkpoint.save_best is None



def seeded_weights_and_model() -> tuple[torch.Tensor, torch.nn.Module]:
    """A small seeded network and its initial weights, flat."""
    torch.manual_seed(0)
    model = torch.nn.Sequential(torch.nn.Linear(6, 8), torch.nn.ReLU(), torch.nn.Linear(8, 2))
    return torch.cat([p.detach().flatten() for p in model.parameters()]), model


def test_exp2_cpu_steps_exp2s_adamw_fused_to_the_same_weights():
    """exp2_cpu's optimiser is exp2's AdamW in torch's fused implementation: built by mmengine
    from the config, three steps leave the weights where the unfused loop leaves them."""
    exp2, cpu = load('exp2'), load('exp2_cpu')
    assert cpu.optim_wrapper.optimizer == dict(exp2.optim_wrapper.optimizer, fused=True)
    weights = {}
    for name, config in (('fused', cpu.optim_wrapper), ('loop', exp2.optim_wrapper)):
        initial, model = seeded_weights_and_model()
        wrapper = build_optim_wrapper(model, copy.deepcopy(config))
        assert bool(wrapper.optimizer.defaults.get('fused')) is (name == 'fused')
        for step in range(3):
            inputs = torch.linspace(-1, 1, 24).reshape(4, 6) * (step + 1)
            wrapper.update_params(model(inputs).square().mean())
        weights[name] = torch.cat([p.detach().flatten() for p in model.parameters()])
    assert not torch.allclose(weights['loop'], initial, atol=1e-4)  # the steps moved them
    assert torch.allclose(weights['fused'], weights['loop'], atol=1e-6)
