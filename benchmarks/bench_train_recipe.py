"""Where the time of an exp2_cpu training goes, for the previous recipe and for today's
``configs/tr3d/exp2_cpu.py``, measured side by side in one run, and the whole-run ratio.

    .venv/bin/python benchmarks/bench_train_recipe.py [--rooms-per-area 4] [--points 1000000]
                                                      [--iters 16] [--warmup 4]
                                                      [--profile-iters 8] [--seed 0]
                                                      [--workers 2] [--fork-tools]

The previous recipe is the same config with four ``--cfg-options``: TR3D's neck keeping every
voxel its generative upsampling creates (``model.neck.generated_reach=None``), the training
loader finding each room's floor, ceiling and walls anew in every epoch
(``ThinRoomStructure(cached_rooms=0)``), a validation after every epoch
(``train_cfg.val_interval=1``) and AdamW's loop over the weights instead of its fused step
(``optim_wrapper.optimizer.fused=False``).

The generator writes ``--rooms-per-area`` rooms of ``--points`` points into areas 7, 8 and 9 of
a temporary folder and ``tools/create_data.py`` converts them. Then, for each recipe:

1. **Per step**, in this process with one thread: ``--profile-iters`` training iterations of
   2 rooms (one training process's share of the batch of 4) timed step by step in CPU seconds:
   the loader's transforms, voxelisation, backbone, neck, head and losses, backward pass and
   optimiser step (the first two iterations not counted), and one test room's inference (a
   validation room).
2. **Whole iterations**, as ``make exp2-cpu`` trains: 2 processes of one thread
   (``tools/dist_train.sh``, gloo), ``--iters`` iterations of 4 rooms; the Runner's median
   seconds per iteration after ``--warmup``.

The whole run of ``make exp2-cpu`` (50 rooms per area, the config's epochs and repeats) is then
its iterations times the seconds per iteration plus its validations: the area-9 rooms times
the seconds per validation room, shared by the 2 processes. The last line is the ratio of the
two whole runs. It needs an idle machine: another job on the cores slows the recipes differently.
"""
import argparse
import importlib
import os
import statistics
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

from benchmarks.bench_dist_train import (BATCH, CONFIG, TRAIN_ROOMS_AREAS,
                                         add_training_run_options, check_iterations, make_data,
                                         train)
from synthdet.cli import OneLineParser

EXP2_ROOMS_PER_AREA = 50  # make exp2-cpu's areas 7, 8 and 9
PROFILE_ROOMS = 2  # rooms of one training process per iteration (batch 4 in 2 processes)
UNCOUNTED = 2  # first profiled iterations left out (allocations, first kernel maps)
STEPS = ('loading', 'structure', 'sampling', 'augmentations', 'voxelize', 'backbone', 'neck',
         'head + losses', 'backward', 'optimiser')
LOADING = ('LoadPointsFromFile', 'LoadAnnotations3D')


def previous_recipe(cfg) -> dict[str, object]:
    """The ``--cfg-options`` (key -> value) that turn today's exp2_cpu config into the
    previous recipe."""
    options: dict[str, object] = {
        'model.neck.generated_reach': None,
        'train_cfg.val_interval': 1,
        'optim_wrapper.optimizer.fused': False
    }
    for index, dataset in enumerate(cfg.train_dataloader.dataset.dataset.datasets):
        for step, transform in enumerate(dataset.pipeline):
            if transform.type == 'ThinRoomStructure':
                options[f'train_dataloader.dataset.dataset.datasets.{index}.pipeline.{step}'
                        '.cached_rooms'] = 0
    return options


def option_strings(options: dict[str, object]) -> list[str]:
    """``--cfg-options`` arguments of ``options``."""
    return [f'{key}={value}' for key, value in options.items()]


def step_of(transform_name: str) -> str:
    """The breakdown row a loader transform counts in."""
    if transform_name in LOADING:
        return 'loading'
    if transform_name == 'ThinRoomStructure':
        return 'structure'
    if transform_name == 'PointSample':
        return 'sampling'
    return 'augmentations'


def timed(seconds: dict[str, list[float]], step: str, call, *args):
    """``call(*args)``, adding its CPU seconds to ``seconds[step]``."""
    start = time.process_time()
    result = call(*args)
    seconds[step].append(time.process_time() - start)
    return result


def profile(data: Path, options: dict[str, object], iterations: int,
            seed: int) -> tuple[dict[str, float], float]:
    """CPU seconds per training iteration of ``PROFILE_ROOMS`` rooms for each step of
    ``STEPS``, and per validation room, of the config with ``options``."""
    import numpy as np
    import torch
    from mmengine.config import Config
    from mmengine.dataset import pseudo_collate
    from mmengine.optim import build_optim_wrapper
    from mmengine.registry import init_default_scope
    from mmdet3d.registry import DATASETS, MODELS

    cfg = Config.fromfile(Path(__file__).resolve().parents[1] / CONFIG)
    cfg.merge_from_dict(options)
    init_default_scope('mmdet3d')
    for module in cfg.custom_imports['imports']:
        importlib.import_module(module)
    train_set = DATASETS.build(
        dict(cfg.train_dataloader.dataset.dataset.datasets[0], data_root=f'{data}/'))
    torch.manual_seed(seed)
    np.random.seed(seed)
    model = MODELS.build(cfg.model)
    model.init_weights()
    model.train()
    optimiser = build_optim_wrapper(model, cfg.optim_wrapper)
    seconds: dict[str, list[float]] = defaultdict(list)
    for iteration in range(iterations + UNCOUNTED):
        if iteration == UNCOUNTED:
            seconds.clear()
        rooms = []
        for room in range(PROFILE_ROOMS):
            results = dict(
                train_set.get_data_info((iteration * PROFILE_ROOMS + room) % len(train_set)),
                box_type_3d=train_set.box_type_3d, box_mode_3d=train_set.box_mode_3d)
            for transform in train_set.pipeline.transforms:
                results = timed(seconds, step_of(type(transform).__name__), transform, results)
            rooms.append(results)
        batch = model.data_preprocessor(pseudo_collate(rooms), True)
        voxels = timed(seconds, 'voxelize', model.voxelize, batch['inputs']['points'])
        stages = timed(seconds, 'backbone', model.backbone, voxels)
        levels = timed(seconds, 'neck', model.neck, stages)
        losses = timed(seconds, 'head + losses', model.bbox_head.loss, levels,
                       batch['data_samples'])
        loss, _ = model.parse_losses(losses)
        timed(seconds, 'backward', loss.backward)
        timed(seconds, 'optimiser', lambda: (optimiser.step(), optimiser.zero_grad()))
    per_iteration = {step: sum(seconds[step]) / iterations for step in STEPS}
    return per_iteration, validation_room_seconds(cfg, data, model)


def validation_room_seconds(cfg, data: Path, model) -> float:
    """CPU seconds of one test-pipeline room's loading and inference (the median of three)."""
    import torch
    from mmengine.dataset import pseudo_collate
    from mmdet3d.registry import DATASETS

    test_set = DATASETS.build(dict(cfg.test_dataloader.dataset, data_root=f'{data}/'))
    model.eval()
    seconds = []
    with torch.no_grad():
        for index in range(3):
            start = time.process_time()
            model.test_step(pseudo_collate([test_set[index % len(test_set)]]))
            seconds.append(time.process_time() - start)
    return statistics.median(seconds)


def whole_run_minutes(cfg, seconds_per_iteration: float, validation_room: float,
                      val_interval: int) -> float:
    """Minutes of ``make exp2-cpu``'s training: its iterations and its validations of area 9
    (shared by 2 processes)."""
    epochs = cfg.train_cfg.max_epochs
    rooms = EXP2_ROOMS_PER_AREA * len(TRAIN_ROOMS_AREAS) * cfg.train_dataloader.dataset.times
    iterations = epochs * rooms // BATCH
    validations = epochs // val_interval
    return (iterations * seconds_per_iteration +
            validations * EXP2_ROOMS_PER_AREA * validation_room / 2) / 60


def main(argv: list[str] | None = None) -> None:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    add_training_run_options(parser, 'recipe')
    parser.add_argument('--profile-iters', type=int, default=8,
                        help='iterations profiled step by step per recipe')
    args = parser.parse_args(argv)
    check_iterations(parser, args)
    if args.profile_iters < 1:
        parser.error('--profile-iters must be at least 1')
    train_rooms = args.rooms_per_area * len(TRAIN_ROOMS_AREAS)
    from mmengine.config import Config
    os.environ['OMP_NUM_THREADS'] = '1'
    import torch
    torch.set_num_threads(1)
    cfg = Config.fromfile(Path(__file__).resolve().parents[1] / CONFIG)
    recipes = {'previous': previous_recipe(cfg), 'today': {}}
    steps, iteration, minutes = {}, {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / 'data'
        make_data(data, args.rooms_per_area, args.points, args.seed, args.workers,
                  args.fork_tools)
        for name, options in recipes.items():
            steps[name], validation_room = profile(data, options, args.profile_iters, args.seed)
            times = train(data, Path(tmp) / f'work_{name}', 2, 1,
                          args.iters * BATCH // train_rooms, args.seed, option_strings(options),
                          args.fork_tools)
            if len(times) != args.iters:
                sys.exit(f'{name} recipe: logged {len(times)} iterations, expected {args.iters}')
            iteration[name] = statistics.median(times[args.warmup:])
            val_interval = options.get('train_cfg.val_interval', cfg.train_cfg.val_interval)
            minutes[name] = whole_run_minutes(cfg, iteration[name], validation_room, val_interval)
            steps[name]['validation room'] = validation_room
    print_report(args, steps, iteration, minutes)


def print_report(args: argparse.Namespace, steps: dict[str, dict[str, float]],
                 iteration: dict[str, float], minutes: dict[str, float]) -> None:
    """The per-step table, the iteration times and the whole-run ratio."""
    previous, today = steps['previous'], steps['today']
    print(f'{CONFIG}: rooms of {args.points} generated points, {os.cpu_count()} cores')
    print(f'CPU seconds per iteration of {PROFILE_ROOMS} rooms, one thread '
          f'({args.profile_iters} iterations):')
    print(f"{'step':<16} {'previous':>9} {'today':>9} {'ratio':>7}")
    for step in (*STEPS, 'validation room'):
        ratio = f'{previous[step] / today[step]:.2f}x' if today[step] > 0 else '-'
        print(f'{step:<16} {previous[step]:>9.3f} {today[step]:>9.3f} {ratio:>7}')
    total = {name: sum(steps[name][step] for step in STEPS) for name in steps}
    print(f"{'iteration':<16} {total['previous']:>9.3f} {total['today']:>9.3f} "
          f"{total['previous'] / total['today']:>6.2f}x")
    print(f'2 processes x 1 thread, {BATCH} rooms per iteration, median of '
          f'{args.iters - args.warmup}: previous {iteration["previous"]:.2f} s, today '
          f'{iteration["today"]:.2f} s ({iteration["previous"] / iteration["today"]:.2f}x)')
    print(f'make exp2-cpu training: previous {minutes["previous"]:.0f} min, today '
          f'{minutes["today"]:.0f} min: x{minutes["previous"] / minutes["today"]:.2f} faster')


if __name__ == '__main__':
    main()
