"""The domain-shift benchmark (benchmarks/bench_domain_shift.py): its configs, its report, and
one whole run at a tiny scale through the real generator, converter, Runner and test tool (run
in this process, its tools forked from one process that imported the stack: ``--fork-tools``)."""
from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path

import pytest
from mmengine.config import Config

from benchmarks.bench_domain_shift import (MIXED, TEST_AREAS, TRAIN_AREAS, DomainShift, Settings,
                                           StepError, held_out, main, report)

REPO = Path(__file__).resolve().parents[2]
LAST_LINE = re.compile(r'domain shift: worst held-out mAP@0\.25 (\d\.\d{3}|-) vs (\d\.\d{3}|-)')
# profiles of the generator's existing keys, standing in for generator/profiles/*.json
PROFILES = {
    'paper': {
        'scanner': {
            'aim_at_objects': False
        }
    },
    'noisy': {
        'scanner': {
            'range_noise': 0.01,
            'angular_jitter': 0.002,
            'dropout': 0.1
        }
    },
}
# the smallest run that still trains both models and tests each on both profiles: one room per
# area, one iteration; 100 sampled points keep the detector's voxels (its cost) few
TINY = [
    '--rooms-train', '1', '--rooms-test', '1', '--iters', '1', '--points', '2000',
    '--sample-points', '100', '--seed', '3', '--test-profiles', 'paper', 'mixed',
    '--progress-every', '5'
]


@pytest.mark.parametrize('model', sorted(TRAIN_AREAS))
def test_configs_train_one_area_by_iterations_without_validation(model):
    name = 'domain_shift_cpu' if model == 'paper' else 'domain_shift_mixed_cpu'
    cfg = Config.fromfile(REPO / f'configs/tr3d/{name}.py', import_custom_modules=False)
    datasets = cfg.train_dataloader.dataset.dataset.datasets
    assert [d.ann_file for d in datasets] == [f's3dis_infos_Area_{TRAIN_AREAS[model]}.pkl']
    assert cfg.test_dataloader.dataset.ann_file == f's3dis_infos_Area_{TEST_AREAS[model]}.pkl'
    assert {d.data_root for d in datasets} == {cfg.test_dataloader.dataset.data_root}
    assert cfg.model.voxel_size == 0.02
    assert [s.num_points for s in datasets[0].pipeline if s.type == 'PointSample'] == [40000]
    assert cfg.train_cfg == dict(type='IterBasedTrainLoop', max_iters=cfg.max_iters)
    assert cfg.param_scheduler.milestones == [cfg.max_iters * 4 // 5]
    assert cfg.val_dataloader is None and cfg.val_cfg is None
    # the mixed model switches the robustness augmentations on where the checkout has them
    has_robustness = 'robust_augmentations' in Config.fromfile(
        REPO / 'configs/tr3d/_base_/s3dis-synthdet.py', import_custom_modules=False)
    assert cfg.get('robustness', False) == (model == MIXED and has_robustness)


def table(mean25: float, mean50: float) -> dict:
    row = {'table': mean25, 'chair': None, 'mean': mean25}
    return {
        'classes': ['table', 'chair'],
        'rows': {
            'mAP@0.25': row,
            'mAP@0.5': dict(row, table=mean50, mean=mean50)
        }
    }


def test_report_names_held_out_profiles_drops_and_the_worst_of_each_model():
    profiles = list(TEST_AREAS)
    assert held_out('paper', profiles) == [p for p in profiles if p != 'paper']
    assert held_out(MIXED, profiles) == [p for p in profiles if p != MIXED]
    scores = {
        'paper': {
            p: 0.9 - 0.1 * i
            for i, p in enumerate(profiles)
        },
        MIXED: {
            p: 0.95 - 0.01 * i
            for i, p in enumerate(profiles)
        }
    }
    models = {}
    for model, by_profile in scores.items():
        drops = {
            p: {
                'mAP@0.25': by_profile[model] - by_profile[p],
                'mAP@0.5': 0.0
            }
            for p in held_out(model, profiles)
        }
        models[model] = {
            'config': f'{model}.py',
            'training_area': TRAIN_AREAS[model],
            'robustness_augmentations': model == MIXED,
            'in_domain_profile': model,
            'in_domain': {
                'mAP@0.25': by_profile[model],
                'mAP@0.5': 0.5
            },
            'held_out': list(drops),
            'drops': drops,
            'worst_held_out_mAP@0.25': min(by_profile[p] for p in drops)
        }
    results = {
        'settings': dict(rooms_train=4, rooms_test=2, iters=5, points=10, sample_points=5, seed=0),
        'sets': {
            f'test_{p}': {
                'area': a,
                'rooms': 2
            }
            for p, a in TEST_AREAS.items()
        },
        'classes': ['table', 'chair'],
        'tables': {
            p: {
                m: table(scores[m][p], 0.5)['rows']
                for m in scores
            }
            for p in profiles
        },
        'models': models,
        'goal': {
            'mixed_largest_drop': 0.08,
            'met': False
        },
    }
    text = report(results).splitlines()
    assert text[-1] == 'domain shift: worst held-out mAP@0.25 0.200 vs 0.890'
    assert text[1].endswith('(profile paper), robustness augmentations off')
    assert text[2].endswith('(profile mixed), robustness augmentations on')
    assert text[-2].endswith('NOT met (largest drop +0.080)')
    for profile in profiles:
        assert f'Table 3 on {profile} (area {TEST_AREAS[profile]}, 2 rooms):' in text
    assert 'paper model: in-domain (paper test rooms) mAP@0.25 0.900, mAP@0.5 0.500; held out: ' \
        'tls, tablet, noisy, shaded, colorless, clutter, mixed' in text
    assert any(
        re.fullmatch(r'\s*tls\s+0\.800\s+\+0\.100\s+0\.500\s+\+0\.000', line) for line in text)
    first = text.index('Table 3 on tls (area 22, 2 rooms):')
    assert text[first + 2].split() == ['paper', 'mAP@0.25', '0.800', '-', '0.800']


def test_missing_profile_files_and_in_domain_tests_are_refused_before_any_work(tmp_path):
    settings = Settings(1, 1, 1, 100, 100, 0)
    bench = DomainShift(tmp_path / 'work', settings, tmp_path, ['paper', 'noisy', MIXED])
    with pytest.raises(StepError, match=re.escape(str(tmp_path / 'paper.json'))):
        bench.check_inputs()
    (tmp_path / 'paper.json').write_text('{}')
    (tmp_path / 'noisy.json').write_text('{}')
    with pytest.raises(StepError, match="must include 'mixed'"):
        DomainShift(tmp_path / 'work', settings, tmp_path, ['paper', 'noisy']).check_inputs()
    assert not (tmp_path / 'work').exists()


def bench_args(work: Path, profiles: Path, *extra: str) -> list[str]:
    return ['--work-dir', str(work), '--profiles-dir', str(profiles), *TINY, *extra]


def run_bench(capsys, work: Path, profiles: Path, *extra: str) -> subprocess.CompletedProcess:
    """The benchmark's ``main`` in this process, its tools forked (``--fork-tools``)."""
    capsys.readouterr()
    code = main(bench_args(work, profiles, '--fork-tools', *extra))
    out, err = capsys.readouterr()
    return subprocess.CompletedProcess(['bench_domain_shift', *extra], code, out, err)


@pytest.mark.slow
def test_tiny_run_trains_both_models_tests_every_profile_and_resumes(tmp_path, capsys):
    profiles = tmp_path / 'profiles'
    profiles.mkdir()
    for name, profile in PROFILES.items():
        (profiles / f'{name}.json').write_text(json.dumps(profile))
    work = tmp_path / 'work'
    proc = run_bench(capsys, work, profiles)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    lines = proc.stdout.strip().splitlines()
    assert LAST_LINE.fullmatch(lines[-1]), lines[-1]
    results = json.loads((work / 'domain_shift.json').read_text())
    assert (work / 'domain_shift.txt').read_text().strip().splitlines()[-1] == lines[-1]
    assert list(results['tables']) == ['paper', 'mixed']
    assert results['models']['paper']['held_out'] == ['mixed']
    assert results['models'][MIXED]['held_out'] == ['paper']
    worst = [results['models'][m]['worst_held_out_mAP@0.25'] for m in ('paper', MIXED)]
    assert lines[-1] == 'domain shift: worst held-out mAP@0.25 ' + ' vs '.join(
        '-' if w is None else f'{w:.3f}' for w in worst)
    for profile, rows in results['tables'].items():
        assert sorted(rows) == sorted(TRAIN_AREAS)
        document = json.loads((work / 'tests' / f'paper_on_{profile}.json').read_text())
        assert document['format'] == 'synthdet.table3/1'
        assert document['test_set'] == f's3dis_infos_Area_{TEST_AREAS[profile]}.pkl'
        assert document['config'] == str(work / 'models/paper/domain_shift_paper.py')
        assert document['checkpoint'] == str(work / 'models/paper/iter_1.pth')
        assert rows['paper'] == document['rows']
    # every set was generated with its profile, area and seed
    raw = work / 'data/Stanford3dDataset_v1.2_Aligned_Version'
    for name, info in results['sets'].items():
        metas = sorted((raw / f'Area_{info["area"]}').glob('*/meta.json'))
        assert len(metas) == info['rooms'], name
        generator = json.loads(metas[0].read_text())['generator']
        assert (generator['area'], generator['run_seed']) == (info['area'], info['seed'])
        scanner = generator['config']['scanner']
        expected = PROFILES.get(info['profile'], {}).get('scanner', {})
        assert {k: scanner[k] for k in expected} == expected
        if info['profile'] == MIXED:
            assert scanner['aim_at_objects'] is True and scanner['range_noise'] == 0.0
    for model in TRAIN_AREAS:
        assert (work / 'models' / model / 'iter_1.pth').is_file()
    # a second run finds every output and prints the same result
    again = run_bench(capsys, work, profiles)
    assert again.returncode == 0, again.stderr[-3000:]
    assert again.stdout.count('outputs exist, skipped') == 4
    assert again.stdout.strip().splitlines()[-1] == lines[-1]
    # other settings in the same work folder are refused, naming the settings file
    other = run_bench(capsys, work, profiles, '--iters', '2')
    assert other.returncode == 1 and 'settings.json' in other.stderr
    # a model trained from another version of its config template is refused, not reused
    written = work / 'models' / MIXED / f'domain_shift_{MIXED}.py'
    text = written.read_text()
    assert 'lr=0.001,' in text
    written.write_text(text.replace('lr=0.001,', 'lr=0.002,'))
    stale = run_bench(capsys, work, profiles)
    assert stale.returncode == 1 and f'{written}: this work dir' in stale.stderr
    written.write_text(text)
    # rooms whose annotations give an object points off it (the labelling of an older
    # generator, e.g. TLS mixed pixels) are refused before they are converted or used
    room = next(raw.glob('Area_*/*/meta.json')).parent
    meta = json.loads((room / 'meta.json').read_text())
    annotations = room / 'Annotations'
    obj = next(o['instance'] for o in meta['objects']
               if o['class'] != 'clutter' and (annotations / f'{o["instance"]}.txt').exists())
    wall = (annotations / 'wall_1.txt').read_text()
    with open(annotations / f'{obj}.txt', 'a') as annotation:
        annotation.write(wall)
    refused = run_bench(capsys, work, profiles)
    assert refused.returncode == 1, refused.stdout[-2000:]
    assert f'{room.name}/{obj}' in refused.stderr and 'outside their boxes' in refused.stderr
