"""Domain shift: TR3D trained at CPU scale on the paper profile vs the mixed default, tested on
held-out generator profiles (docs/results.md "Domain shift").

Usage: python benchmarks/bench_domain_shift.py [--work-dir work_dirs/domain_shift]
           [--rooms-train 50] [--rooms-test 20] [--iters 250] [--points 1000000] [--seed 0]
           [--sample-points 40000] [--jobs 2] [--profiles-dir generator/profiles]
           [--test-profiles paper tls ...] [--progress-every 60] [--fork-tools]

Steps, each a tool of the project run as a subprocess with ``OMP_NUM_THREADS=1`` (its output in
``WORK/logs/<step>.log``), ``--jobs`` of them at a time; a step whose outputs exist is skipped,
so a stopped run continues where it stopped (a training resumes from its newest checkpoint):
 1. generate (``python -m generator --config generator/profiles/<profile>.json``; the mixed
    default without a file) the training rooms of the profiles ``paper`` (area 11) and ``mixed``
    (area 12) and the test rooms of every test profile (areas 21-28), one area and one run seed
    (``--seed`` x 100 + area) per set, into ``WORK/data``; then check every room's object
    annotations against the objects' boxes (``synthdet/annotation_check.py``) and refuse rooms
    that give objects points off them (kept rooms of an older generator);
 2. convert every area (``tools/create_data.py``, one run over all the areas, ``--jobs`` workers);
 3. train one model per training profile (``tools/train.py``; configs/tr3d/domain_shift_cpu.py
    and domain_shift_mixed_cpu.py, written to ``WORK/models/<model>/domain_shift_<model>.py``
    with this run's data root, iterations and points);
 4. test each model on each test profile (``tools/test.py``, the paper's Table 3:
    ``WORK/tests/<model>_on_<profile>.json``);
 5. print a Table 3 per test profile, each model's in-domain score and its drop on every held-out
    profile, and write all numbers to ``WORK/domain_shift.json`` (the text to
    ``WORK/domain_shift.txt``).
The defaults (40 training rooms per model, 10 test rooms per profile, 500,000 points per room,
200 iterations) are the scale of the documented run (docs/results.md "Domain shift"): 45 min on
2 cores, of which training 40 min (the two models side by side, about 12 s per iteration each).
Held out: for the paper model every test profile but ``paper``; for the mixed model every
single-profile test area (all but ``mixed``, its in-domain test). The last line compares the
worst held-out mAP@0.25 of the two models. ``--fork-tools`` runs every tool forked from one
process that imported the stack once (``benchmarks/tool_runs.py``): the same steps without a
start-up per tool, for the benchmark's smoke run.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from benchmarks.tool_jobs import Job, run_jobs
from benchmarks.tool_runs import add_fork_tools_option
from projects.synthdet.config_helpers import area_info_file, with_num_points
from synthdet.info_files import RAW_DIR
from synthdet.work_dir import StepError, claim_work_dir
from synthdet.cli import OneLineParser

REPO = Path(__file__).resolve().parents[1]

MIXED = 'mixed'  # the generator's default configuration: no profile file
TRAIN_AREAS = {'paper': 11, MIXED: 12}
TEST_AREAS = {
    'paper': 21,
    'tls': 22,
    'tablet': 23,
    'noisy': 24,
    'shaded': 25,
    'colorless': 26,
    'clutter': 27,
    MIXED: 28,
}
MODEL_CONFIGS = {
    'paper': REPO / 'configs/tr3d/domain_shift_cpu.py',
    MIXED: REPO / 'configs/tr3d/domain_shift_mixed_cpu.py',
}
METRICS = ('mAP@0.25', 'mAP@0.5')
GOAL_DROP = 0.05  # the goal: the mixed model loses at most this mAP@0.25 on a held-out profile
RESULT_FORMAT = 'synthdet.domain_shift/1'


@dataclass(frozen=True)
class Settings:
    """What a work folder holds: changing any of these needs another ``--work-dir``."""
    rooms_train: int
    rooms_test: int
    iters: int
    points: int
    sample_points: int
    seed: int


def held_out(model: str, test_profiles: list[str]) -> list[str]:
    """The test profiles a model did not train on: for the paper model all but ``paper``, for
    the mixed model every single-profile area (all but ``mixed``, its in-domain test)."""
    return [profile for profile in test_profiles if profile != model]


def generation_seed(seed: int, area: int) -> int:
    """The generator's run seed of one set of rooms: every set has its own."""
    return seed * 100 + area


def profile_file(profiles_dir: Path, profile: str) -> Path | None:
    """The generator configuration of a profile; None for the mixed default."""
    return None if profile == MIXED else profiles_dir / f'{profile}.json'


class DomainShift:
    """The benchmark's steps over one work folder."""

    def __init__(self,
                 work_dir: Path,
                 settings: Settings,
                 profiles_dir: Path,
                 test_profiles: list[str],
                 jobs: int = 2,
                 progress_every: float = 60.0,
                 fork_tools: bool = False) -> None:
        self.work = work_dir.resolve()
        self.settings = settings
        self.profiles_dir = profiles_dir.resolve()  # the tools run from the repository
        self.test_profiles = test_profiles
        self.jobs = jobs
        self.progress_every = progress_every
        self.fork_tools = fork_tools
        self.data = self.work / 'data'
        self.raw = self.data / RAW_DIR
        self.logs = self.work / 'logs'
        self.durations: dict[str, float] = {}

    # ------------------------------------------------------------------ inputs and outputs
    def sets(self) -> list[tuple[str, str, int, int]]:
        """(name, profile, area, rooms) of every set of rooms: training sets, then test sets."""
        train = [(f'train_{p}', p, a, self.settings.rooms_train) for p, a in TRAIN_AREAS.items()]
        test = [(f'test_{p}', p, TEST_AREAS[p], self.settings.rooms_test)
                for p in self.test_profiles]
        return train + test

    def check_inputs(self) -> None:
        """Refuse missing profile files and a work folder made with other settings."""
        for _, profile, _, _ in self.sets():
            path = profile_file(self.profiles_dir, profile)
            if path is not None and not path.is_file():
                raise StepError(f'{path}: no such generator profile (profile {profile!r})')
        for model in TRAIN_AREAS:
            if model not in self.test_profiles:
                raise StepError(f'--test-profiles must include {model!r}: the {model} model\'s '
                                'in-domain test')
        claim_work_dir(self.work / 'settings.json',
                       dict(format=RESULT_FORMAT, **self.settings.__dict__))

    def rooms_in(self, area: int) -> int:
        folder = self.raw / f'Area_{area}'
        return len(list(folder.glob('*/meta.json'))) if folder.is_dir() else 0

    def info_file(self, area: int) -> Path:
        return self.data / area_info_file(area)

    def model_dir(self, model: str) -> Path:
        return self.work / 'models' / model

    def model_config(self, model: str) -> Path:
        """The config the model trains and tests with; its name heads the Table 3 text."""
        return self.model_dir(model) / f'domain_shift_{model}.py'

    def final_checkpoint(self, model: str) -> Path:
        return self.model_dir(model) / f'iter_{self.settings.iters}.pth'

    def table_file(self, model: str, profile: str) -> Path:
        return self.work / 'tests' / f'{model}_on_{profile}.json'

    # ------------------------------------------------------------------ steps
    def run_step(self, step: str, jobs: list[Job]) -> None:
        """Run the jobs of one step (those whose outputs are missing) and time the step."""
        if not jobs:
            print(f'[domain shift] {step}: outputs exist, skipped', flush=True)
            return
        print(f'[domain shift] {step}: {len(jobs)} job(s), {self.jobs} at a time', flush=True)
        start = time.monotonic()
        run_jobs(jobs, self.jobs, self.progress_every, 'domain shift', self.fork_tools)
        self.durations[step] = round(time.monotonic() - start, 1)
        print(f'[domain shift] {step}: done in {self.durations[step]:.0f} s', flush=True)

    def generate_jobs(self) -> list[Job]:
        jobs = []
        for name, profile, area, rooms in self.sets():
            if self.rooms_in(area) >= rooms:
                continue
            path = profile_file(self.profiles_dir, profile)
            args = [
                '-m', 'generator', '--out',
                str(self.raw), '--areas',
                str(area), '--rooms-per-area',
                str(rooms), '--points',
                str(self.settings.points), '--seed',
                str(generation_seed(self.settings.seed, area)), '--workers', '1'
            ]
            args += [] if path is None else ['--config', str(path)]
            jobs.append(Job(f'generate {name} (area {area})', args, self.logs / f'gen_{name}.log'))
        return jobs

    def convert_jobs(self) -> list[Job]:
        """One converter run for every area without its info file (``--jobs`` workers over the
        rooms): one tool start-up instead of one per set."""
        areas = [str(area) for _, _, area, _ in self.sets() if not self.info_file(area).is_file()]
        if not areas:
            return []
        return [
            Job(f'convert areas {" ".join(areas)}', [
                'tools/create_data.py', 's3dis', '--root-path',
                str(self.data), '--out-dir',
                str(self.data), '--areas', *areas, '--workers',
                str(self.jobs)
            ], self.logs / 'convert.log')
        ]

    def model_config_text(self, model: str) -> str:
        """The model's config: its template with this run's data root, schedule and points, as
        one self-contained file."""
        from mmengine.config import Config

        cfg = Config.fromfile(MODEL_CONFIGS[model], import_custom_modules=False)
        data_root = f'{self.data}/'
        points, iters = self.settings.sample_points, self.settings.iters
        for dataset in cfg.train_dataloader.dataset.dataset.datasets:
            dataset.data_root = data_root
            dataset.pipeline = with_num_points(dataset.pipeline, points)
        test_set = cfg.test_dataloader.dataset
        test_set.data_root = data_root
        test_set.pipeline = with_num_points(test_set.pipeline, points)
        # the config's variables too, so that the written file reads as what it runs
        cfg.data_root, cfg.num_points, cfg.max_iters = data_root, points, iters
        for name in ('train_pipeline', 'test_pipeline'):
            cfg[name] = with_num_points(cfg[name], points)
        cfg.train_cfg.max_iters = iters
        cfg.param_scheduler.end = iters
        cfg.param_scheduler.milestones = [iters * 4 // 5]
        cfg.default_hooks.checkpoint.interval = max(1, iters // 4)
        cfg.randomness = dict(seed=self.settings.seed)
        return (f'# {MODEL_CONFIGS[model].relative_to(REPO)} with the data in {data_root}, '
                f'{iters} iterations, {points} sampled points; written by '
                f'benchmarks/bench_domain_shift.py.\n' + cfg.pretty_text)

    def check_model_configs(self) -> None:
        """Refuse a work folder whose models were trained from other configs (a template in
        ``configs/tr3d/`` changed since): their checkpoints and tables would be stale."""
        from mmengine.config import Config

        def settings(cfg: Config) -> dict:  # tools/train.py adds the run's launcher and work dir
            return {k: v for k, v in cfg.to_dict().items() if k not in ('launcher', 'work_dir')}

        for model in TRAIN_AREAS:
            path = self.model_config(model)
            if not path.is_file():
                continue
            wanted = Config.fromstring(self.model_config_text(model), '.py')
            if settings(Config.fromfile(path, import_custom_modules=False)) != settings(wanted):
                raise StepError(f'{path}: this work dir\'s {model} model was trained from another '
                                f'version of {MODEL_CONFIGS[model].relative_to(REPO)}; choose '
                                'another --work-dir')

    def write_model_config(self, model: str) -> Path:
        """Write the model's config next to its checkpoints; returns its path."""
        path = self.model_config(model)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(self.model_config_text(model))
        return path

    def train_jobs(self) -> list[Job]:
        jobs = []
        for model in TRAIN_AREAS:
            if self.final_checkpoint(model).is_file():
                continue
            config = self.model_config(model)
            if not config.is_file():
                self.write_model_config(model)
            resume = ['--resume'] if list(self.model_dir(model).glob('iter_*.pth')) else []
            jobs.append(
                Job(f'train {model}', [
                    'tools/train.py',
                    str(config), '--work-dir',
                    str(self.model_dir(model)), *resume
                ], self.logs / f'train_{model}.log'))
        return jobs

    def test_jobs(self) -> list[Job]:
        return [
            Job(f'test {model} on {profile}', [
                'tools/test.py',
                str(self.model_config(model)),
                str(self.final_checkpoint(model)), '--work-dir',
                str(self.work / 'tests' / f'{model}_on_{profile}'), '--out',
                str(self.table_file(model, profile)), '--cfg-options',
                f'test_dataloader.dataset.ann_file={area_info_file(TEST_AREAS[profile])}'
            ], self.logs / f'test_{model}_on_{profile}.log') for model in TRAIN_AREAS
            for profile in self.test_profiles if not self.table_file(model, profile).is_file()
        ]

    def check_annotations(self) -> None:
        """Refuse generated rooms whose objects' annotations hold points off the objects
        (``tools/check_annotations.py``): kept data of an older generator, whose true boxes
        differ from what the generator writes now."""
        from synthdet.annotation_check import check_room, describe, offenders

        areas = sorted({area for _, _, area, _ in self.sets()})
        rooms = [
            meta.parent for area in areas
            for meta in sorted((self.raw / f'Area_{area}').glob('*/meta.json'))
        ]
        bad = offenders([fit for room in rooms for fit in check_room(room)])
        print(f'[domain shift] annotations of {len(rooms)} rooms checked against their boxes: '
              f'{len(bad)} objects with more than 1 % of their points off them', flush=True)
        if bad:
            raise StepError(f'{self.raw}: {len(bad)} objects have annotated points outside '
                            f'their boxes, e.g. {describe(bad[0])} (rooms of an older '
                            f'generator?); empty {self.work} or choose another --work-dir')

    def run_all(self) -> dict:
        """Run every step whose outputs are missing; returns the results document."""
        self.check_inputs()
        self.run_step('generate', self.generate_jobs())
        self.check_annotations()
        self.run_step('convert', self.convert_jobs())
        self.check_model_configs()
        self.run_step('train', self.train_jobs())
        self.run_step('test', self.test_jobs())
        tables = {
            model: {
                profile: json.loads(self.table_file(model, profile).read_text())
                for profile in self.test_profiles
            }
            for model in TRAIN_AREAS
        }
        return self.results(tables)

    # ------------------------------------------------------------------ results
    def robustness(self, model: str) -> bool:
        """Whether the model's config switched the robustness augmentations on."""
        from mmengine.config import Config
        return bool(
            Config.fromfile(self.model_config(model),
                            import_custom_modules=False).get('robustness', False))

    def results(self, tables: dict[str, dict[str, dict]]) -> dict:
        """The results document: settings, sets, every Table 3 row, in-domain scores, drops."""
        models = {}
        for model in TRAIN_AREAS:
            in_domain = tables[model][model]['rows']
            drops = {
                profile: {
                    metric:
                    _difference(in_domain[metric]['mean'],
                                tables[model][profile]['rows'][metric]['mean'])
                    for metric in METRICS
                }
                for profile in held_out(model, self.test_profiles)
            }
            held = [tables[model][p]['rows']['mAP@0.25']['mean'] for p in drops]
            models[model] = {
                'config': str(MODEL_CONFIGS[model].relative_to(REPO)),
                'training_profile': model,
                'training_area': TRAIN_AREAS[model],
                'robustness_augmentations': self.robustness(model),
                'in_domain_profile': model,
                'in_domain': {
                    metric: in_domain[metric]['mean']
                    for metric in METRICS
                },
                'held_out': list(drops),
                'drops': drops,
                'worst_held_out_mAP@0.25': _minimum(held),
            }
        mixed_drops = [d['mAP@0.25'] for d in models[MIXED]['drops'].values()]
        return {
            'format': RESULT_FORMAT,
            'settings': self.settings.__dict__,
            'sets': {
                name: {
                    'profile': profile,
                    'area': area,
                    'rooms': rooms,
                    'seed': generation_seed(self.settings.seed, area)
                }
                for name, profile, area, rooms in self.sets()
            },
            'classes': next(iter(tables[MIXED].values()))['classes'],
            'tables': {
                profile: {
                    model: tables[model][profile]['rows']
                    for model in TRAIN_AREAS
                }
                for profile in self.test_profiles
            },
            'models': models,
            'goal': {
                'max_drop_mAP@0.25':
                GOAL_DROP,
                'mixed_largest_drop':
                _maximum(mixed_drops),
                'met':
                bool(mixed_drops) and all(d is not None and d <= GOAL_DROP for d in mixed_drops),
            },
            'durations_s': self.durations,
        }


def _difference(reference: float | None, value: float | None) -> float | None:
    if reference is None or value is None or math.isnan(reference) or math.isnan(value):
        return None
    return reference - value


def _minimum(values: list[float | None]) -> float | None:
    known = [v for v in values if v is not None and not math.isnan(v)]
    return min(known) if known else None


def _maximum(values: list[float | None]) -> float | None:
    known = [v for v in values if v is not None and not math.isnan(v)]
    return max(known) if known else None


def _number(value: float | None, signed: bool = False) -> str:
    if value is None or math.isnan(value):
        return '-'
    return f'{value:+.3f}' if signed else f'{value:.3f}'


def report(results: dict) -> str:
    """The benchmark's text: a Table 3 per test profile, each model's in-domain score and
    drops, the goal, and as the last line the worst held-out mAP@0.25 of both models."""
    classes = [*results['classes'], 'mean']
    settings = results['settings']
    sets = results['sets']
    lines = [
        f'Domain shift: TR3D at CPU scale (2 cm voxels, {settings["sample_points"]} sampled '
        f'points, {settings["iters"]} iterations of batch 4), trained on '
        f'{settings["rooms_train"]} generated rooms of one profile, tested on '
        f'{settings["rooms_test"]} rooms per test profile ({settings["points"]} points per '
        f'generated room, seed {settings["seed"]}).'
    ]
    for model, info in results['models'].items():
        robustness = 'on' if info['robustness_augmentations'] else (
            'off (not in this checkout)' if model == MIXED else 'off')
        lines.append(f'  {model} model: {info["config"]}, trained on area '
                     f'{info["training_area"]} (profile {model}), robustness augmentations '
                     f'{robustness}')
    width = max(10, *(len(c) + 1 for c in classes))
    for profile, rows in results['tables'].items():
        test_set = sets[f'test_{profile}']
        lines += [
            '', f'Table 3 on {profile} (area {test_set["area"]}, {test_set["rooms"]} rooms):',
            'model   metric   ' + ''.join(c.rjust(width) for c in classes)
        ]
        for model, table in rows.items():
            for metric in METRICS:
                cells = (_number(table[metric][c]) for c in classes)
                lines.append(f'{model:<8}{metric:<9}' + ''.join(c.rjust(width) for c in cells))
    for model, info in results['models'].items():
        lines += [
            '', f'{model} model: in-domain ({info["in_domain_profile"]} test rooms) mAP@0.25 '
            f'{_number(info["in_domain"]["mAP@0.25"])}, mAP@0.5 '
            f'{_number(info["in_domain"]["mAP@0.5"])}; held out: {", ".join(info["held_out"])}',
            f'  {"profile":<12}{"mAP@0.25":>9}{"drop":>8}{"mAP@0.5":>9}{"drop":>8}'
        ]
        for profile, drop in info['drops'].items():
            table = results['tables'][profile][model]
            lines.append(f'  {profile:<12}{_number(table["mAP@0.25"]["mean"]):>9}'
                         f'{_number(drop["mAP@0.25"], True):>8}'
                         f'{_number(table["mAP@0.5"]["mean"]):>9}'
                         f'{_number(drop["mAP@0.5"], True):>8}')
    goal = results['goal']
    paper, mixed = results['models']['paper'], results['models'][MIXED]
    if results.get('durations_s'):
        lines += [
            '', 'wall time of the steps run now: ' +
            ', '.join(f'{step} {seconds:.0f} s'
                      for step, seconds in results['durations_s'].items())
        ]
    lines += [
        '', f'goal: the mixed model loses at most {GOAL_DROP} mAP@0.25 on every held-out '
        f'profile against its in-domain score: {"met" if goal["met"] else "NOT met"} (largest '
        f'drop {_number(goal["mixed_largest_drop"], True)})',
        f'domain shift: worst held-out mAP@0.25 {_number(paper["worst_held_out_mAP@0.25"])} vs '
        f'{_number(mixed["worst_held_out_mAP@0.25"])}'
    ]
    return '\n'.join(lines)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = OneLineParser(description=__doc__.split('\n\n')[0].replace('\n', ' '))
    parser.add_argument('--work-dir', type=Path, default=REPO / 'work_dirs/domain_shift')
    parser.add_argument(
        '--rooms-train', type=int, default=40, help='training rooms per training profile')
    parser.add_argument('--rooms-test', type=int, default=10, help='test rooms per test profile')
    parser.add_argument('--iters', type=int, default=200, help='training iterations (batch 4)')
    parser.add_argument('--points', type=int, default=500_000, help='points per generated room')
    parser.add_argument(
        '--sample-points', type=int, default=40_000, help='points the detector samples per room')
    parser.add_argument('--seed', type=int, default=0, help='generator and training seed')
    parser.add_argument('--jobs', type=int, default=2, help='tool processes at a time')
    parser.add_argument('--profiles-dir', type=Path, default=REPO / 'generator/profiles')
    parser.add_argument(
        '--test-profiles',
        nargs='+',
        choices=list(TEST_AREAS),
        default=list(TEST_AREAS),
        help='test profiles (default all; paper and mixed are needed)')
    parser.add_argument(
        '--progress-every',
        type=float,
        default=60.0,
        help='seconds between progress lines of running steps')
    add_fork_tools_option(parser)
    args = parser.parse_args(argv)
    for name in ('rooms_train', 'rooms_test', 'iters', 'points', 'sample_points', 'jobs'):
        if getattr(args, name) < 1:
            parser.error(f'--{name.replace("_", "-")} must be >= 1')
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    settings = Settings(args.rooms_train, args.rooms_test, args.iters, args.points,
                        args.sample_points, args.seed)
    bench = DomainShift(args.work_dir, settings, args.profiles_dir,
                        list(dict.fromkeys(args.test_profiles)), args.jobs, args.progress_every,
                        args.fork_tools)
    try:
        results = bench.run_all()
    except StepError as error:
        print(f'bench_domain_shift: error: {error}', file=sys.stderr)
        return 1
    text = report(results)
    (bench.work / 'domain_shift.json').write_text(json.dumps(results, indent=1) + '\n')
    (bench.work / 'domain_shift.txt').write_text(text + '\n')
    print(f'[domain shift] numbers in {bench.work / "domain_shift.json"}', flush=True)
    print(text, flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
