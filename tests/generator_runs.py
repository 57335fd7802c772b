"""Generate rooms with the generator's own command line, in the test process."""
from pathlib import Path


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
