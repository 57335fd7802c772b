"""The layout modules import one way: placement, then the furnishing rules, room kinds and halls,
then the room layout on top, so none of them needs the room layout (no import loop)."""
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize(
    'module',
    ['generator.placement', 'generator.furnish', 'generator.room_kinds', 'generator.hall_layout'])
def test_layout_parts_do_not_import_the_room_layout(module):
    result = subprocess.run([sys.executable, '-c', f'import sys, {module}; print(*sys.modules)'],
                            cwd=REPO,
                            capture_output=True,
                            text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr
    assert 'generator.layout' not in result.stdout.split()
