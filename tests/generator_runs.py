"""Generate rooms with the generator's own command line, in the test process, read back what
they record, and check the errors of a bad generator configuration."""
import json
from pathlib import Path
from typing import Iterator

import pytest

from generator.config import ConfigError, load_config


def generate_rooms(out: Path, area: int, rooms: int, points: int, seed: int,
                   *options: str | Path) -> None:
    """Write ``rooms`` rooms of ``points`` points each to ``out/Area_<area>`` quietly, with the
    generator's ``options`` (e.g. ``--config``, ``--asset-cache``); fails unless it exits 0."""
    import bpy  # noqa: F401  (bpy before open3d: both ship libtbb)
    from generator.__main__ import main
    assert main([
        '--out',
        str(out), '--areas',
        str(area), '--rooms-per-area',
        str(rooms), '--points',
        str(points), '--seed',
        str(seed), *map(str, options), '--quiet'
    ]) == 0


def sensor_records(out: Path, model: str, rooms: int) -> Iterator[tuple[Path, dict]]:
    """The folder and the meta.json sensor record of each room generated below ``out``; asserts
    that there are ``rooms`` of them, each scanned by the sensor ``model`` (no paper path)."""
    metas = sorted(out.rglob('meta.json'))
    assert len(metas) == rooms
    for meta_path in metas:
        meta = json.loads(meta_path.read_text())
        sensor = meta['generator']['sensor']
        assert sensor['model'] == model and 'sensor_path' not in meta['generator']
        yield meta_path.parent, sensor


def assert_sensor_config_error(folder: Path, sensor: str, settings: dict, message: str) -> None:
    """Assert that a configuration file giving the scanner's ``sensor`` these ``settings``
    (written into ``folder``) is refused with an error naming the file and ``message``."""
    config = folder / 'bad.json'
    config.write_text(json.dumps({'scanner': {sensor: settings}}))
    with pytest.raises(ConfigError, match=f'{config}: .*{message}'.replace('[', r'\[')):
        load_config(config)
