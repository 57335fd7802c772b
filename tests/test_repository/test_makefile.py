"""``make exp2-cpu``'s training command, read with ``make -n`` (prints, runs nothing): two
processes by default, ``tools/dist_train.sh`` with the batch of 4 rooms split evenly for
``EXP2_PROCS``, ``tools/train.py`` for one, and a clear refusal of a count that cannot split
it."""
import subprocess
from pathlib import Path

import pytest


ROOT = Path(__file__).resolve().parents[2]


def exp2_dry_run(*variables: str) -> subprocess.CompletedProcess:
    """``make -n exp2-cpu``: the recipe's commands only (no directory lines, also when the
    tests themselves run under make)."""
    return subprocess.run(['make', '--no-print-directory', '-n', 'exp2-cpu', *variables], cwd=ROOT,
                          capture_output=True, text=True, timeout=60)


def _train_command(stdout: str) -> str:
    """The recipe's training command, its continuation lines joined."""
    joined = stdout.replace('\\\n', ' ')
    lines = [line for line in joined.splitlines() if '--work-dir work_dirs/exp2_cpu ' in line]
    assert len(lines) == 1, stdout
    return lines[0]


def test_one_process_trains_with_train_py():
    proc = exp2_dry_run('EXP2_PROCS=1')
    assert proc.returncode == 0, proc.stderr
    command = _train_command(proc.stdout)
    assert 'tools/train.py configs/tr3d/exp2_cpu.py' in command
    assert 'dist_train.sh' not in command and 'batch_size' not in command


@pytest.mark.parametrize('procs, batch', [(None, 2), (2, 2), (4, 1)])
def test_processes_share_the_batch_of_four(procs, batch: int):
    proc = exp2_dry_run(*([f'EXP2_PROCS={procs}'] if procs else []))
    procs = procs or 2  # the default
    assert proc.returncode == 0, proc.stderr
    command = _train_command(proc.stdout)
    assert f'tools/dist_train.sh configs/tr3d/exp2_cpu.py {procs} ' in command
    assert command.split()[-1] == f'train_dataloader.batch_size={batch}'
    tests = [line for line in proc.stdout.splitlines() if 'tools/test.py' in line]
    assert tests and not any('dist_test' in line for line in tests)


def test_uneven_split_is_refused():
    proc = exp2_dry_run('EXP2_PROCS=3')
    assert proc.returncode != 0
    assert 'EXP2_PROCS=3: must be 1, 2 or 4' in proc.stderr


def test_a_variant_config_is_trained_and_tested():
    variant = 'configs/tr3d/tiny.py'
    proc = exp2_dry_run(f'EXP2_CONFIG={variant}')
    assert proc.returncode == 0, proc.stderr
    assert f'tools/dist_train.sh {variant} 2 ' in _train_command(proc.stdout)
    lines = proc.stdout.replace('\\\n', ' ').splitlines()
    tests = [line for line in lines if 'tools/test.py' in line]
    # all of area 9 in one pass and with test-time augmentation, then the loop over the sensors
    assert len(tests) == 3 and ['--tta' in line for line in tests] == [False, True, False]
    assert all(f'tools/test.py {variant} ' in line for line in tests)


def _generator_command(stdout: str) -> str:
    lines = [line for line in stdout.replace('\\\n', ' ').splitlines() if '-m generator' in line]
    assert len(lines) == 1, stdout
    return lines[0]


def test_rooms_are_generated_in_the_mixed_room_kinds_unless_a_profile_is_given():
    default = exp2_dry_run()
    assert default.returncode == 0, default.stderr
    assert _generator_command(default.stdout).split()[-2:] == ['--profile', 'mixed_rooms']
    assert (ROOT / 'generator' / 'profiles' / 'mixed_rooms.json').is_file()
    factory = exp2_dry_run('EXP2_PROFILE=')
    assert '--profile' not in _generator_command(factory.stdout)
    tablet = exp2_dry_run('EXP2_PROFILE=tablet')
    assert _generator_command(tablet.stdout).split()[-2:] == ['--profile', 'tablet']


def test_the_per_sensor_tests_cover_the_sensors_of_the_test_area():
    proc = exp2_dry_run('EXP2_DATA=/data/x')
    assert proc.returncode == 0, proc.stderr
    joined = proc.stdout.replace('\\\n', ' ')
    # the sensors that scanned area 9, listed from its rooms' meta.json; a failed listing stops
    # the recipe instead of looping over nothing
    assert 'sensors=$(.venv/bin/python tools/dataset_stats.py /data/x --areas 9 --sensors) || ' \
        'exit 1;' in joined, proc.stdout
    loop = [line for line in joined.splitlines() if 'for sensor in $sensors' in line]
    assert len(loop) == 1 and '--sensor $sensor' in loop[0], proc.stdout
