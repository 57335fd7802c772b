"""tools/test.py checks its inputs before it loads anything heavy: the test split's info pickle
named by the config (missing, not plain data, not the converter's) is one line naming the file,
exit 2, before the checkpoint is read and the model is built."""
import os
import pickle
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
TINY = REPO / 'configs' / 'tr3d' / 'tiny.py'
INFO_FILE = 's3dis_infos_Area_1.pkl'  # the tiny config's test split: area 1


def run_test_tool(tmp_path: Path, data_root: Path) -> subprocess.CompletedProcess:
    """``tools/test.py`` on the tiny config with its test split in ``data_root`` and a
    checkpoint that does not exist (so only a check made before it can name the info file)."""
    return subprocess.run([
        sys.executable, 'tools/test.py', str(TINY), str(tmp_path / 'missing.pth'), '--work-dir',
        str(tmp_path / 'work'), '--cfg-options', f'test_dataloader.dataset.data_root={data_root}/'
    ],
                          cwd=REPO,
                          capture_output=True,
                          text=True,
                          timeout=300,
                          env={**os.environ, 'OMP_NUM_THREADS': '1'})


def assert_one_line(proc: subprocess.CompletedProcess, *fragments: str) -> None:
    assert proc.returncode == 2, proc.stderr[-3000:]
    assert 'Traceback' not in proc.stderr, proc.stderr[-3000:]
    lines = [line for line in proc.stderr.splitlines() if all(f in line for f in fragments)]
    assert len(lines) == 1, proc.stderr[-3000:]
    assert 'missing.pth' not in proc.stderr  # found before the checkpoint is read


def test_a_missing_info_pickle_is_named_before_the_checkpoint_and_model(tmp_path):
    data_root = tmp_path / 'data'
    data_root.mkdir()
    proc = run_test_tool(tmp_path, data_root)
    assert_one_line(proc, str(data_root / INFO_FILE), 'cannot read')


def test_an_info_pickle_that_is_not_the_converters_is_named(tmp_path):
    data_root = tmp_path / 'data'
    data_root.mkdir()
    (data_root / INFO_FILE).write_bytes(pickle.dumps(['not', 'infos']))
    proc = run_test_tool(tmp_path, data_root)
    assert_one_line(proc, str(data_root / INFO_FILE),
                    'not an info pickle of tools/create_data.py')
