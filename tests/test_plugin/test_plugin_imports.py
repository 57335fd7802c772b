"""The plugin package is light: the data tools and the light library modules load no ML stack.

Each check runs in a fresh interpreter and lists which of torch, mmcv, mmdet, mmdet3d, mmengine
and MinkowskiEngine ended up in ``sys.modules``.
"""
import json
import subprocess
import sys
from pathlib import Path

from tests.s3dis_fixtures import write_synthetic_area

REPO = Path(__file__).resolve().parents[2]
HEAVY = ('torch', 'mmcv', 'mmdet', 'mmdet3d', 'mmengine', 'MinkowskiEngine')
# Runs the code given as the first argument, then prints the heavy modules it loaded.
REPORT_HEAVY = f'''
import json, runpy, sys
code, sys.argv = sys.argv[1], sys.argv[2:]
exec(code)
print(json.dumps(sorted(name for name in {HEAVY!r} if name in sys.modules)))
'''
RUN_TOOL = '''
try:
    runpy.run_path(sys.argv[0], run_name='__main__')
except SystemExit as exit:
    if exit.code:
        raise
'''


def heavy_modules(code: str, *args: str | Path, cwd: Path) -> list[str]:
    """The heavy modules a fresh interpreter holds after running ``code`` with ``args``."""
    done = subprocess.run([sys.executable, '-c', REPORT_HEAVY, code, *map(str, args)],
                          cwd=cwd,
                          capture_output=True,
                          text=True)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.splitlines()[-1])


def test_create_data_and_dataset_stats_run_without_torch_or_mmcv(tmp_path):
    write_synthetic_area(tmp_path, 7, 1, seed=3, points_per_object=40)
    convert = [
        REPO / 'tools' / 'create_data.py', 's3dis', '--root-path', tmp_path, '--out-dir', tmp_path
    ]
    assert heavy_modules(RUN_TOOL, *convert, cwd=tmp_path) == []
    assert (tmp_path / 's3dis_infos_Area_7.pkl').is_file()
    stats = [REPO / 'tools' / 'dataset_stats.py', tmp_path, '--out', tmp_path / 'table1.json']
    assert heavy_modules(RUN_TOOL, *stats, cwd=tmp_path) == []
    assert (tmp_path / 'table1.txt').read_text().startswith('Table 1')


def test_light_library_modules_import_no_ml_stack():
    light = ('projects.synthdet', 'projects.synthdet.datasets',
             'projects.synthdet.datasets.s3dis_converter', 'projects.synthdet.config_helpers',
             'projects.synthdet.evaluation.table1', 'projects.synthdet.evaluation.table3',
             'projects.synthdet.evaluation.table_files')
    assert heavy_modules(f'import {", ".join(light)}', cwd=REPO) == []
    assert heavy_modules('import torch', cwd=REPO) == ['torch']  # the check sees an import
