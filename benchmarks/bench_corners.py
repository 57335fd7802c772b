"""Room corners: the traced-outline method against the paper's method and a convex hull.

    .venv/bin/python benchmarks/bench_corners.py [--rooms 10] [--points 300000]
        [--generate 30] [--generated DIR ...]
    .venv/bin/python benchmarks/bench_corners.py --real SCANS_DIR [--views DIR]

For every room shape (rect, L, U, T, chamfer) and noise setting (clean; LiDAR noise: 1 cm range
noise, 0.03 degree angular jitter, 10 % dropout, dropout patches, 0.05 % outliers) it generates
``--rooms`` rooms (``tests/room_scans.py``, random rotation, furniture, a door and a window)
and prints, for each method, the mean corner error (each true corner to the nearest found
corner, cm), the share of rooms with the right corner count and the share with the corners in
the right clockwise order (what the FreeCAD floor needs). ``--generate N`` runs
``python -m generator`` for N rooms without and N rooms with its noise models (box, L and U
shapes in equal shares, ``--points`` each) in a temporary folder; ``--generated DIR`` adds
existing generator rooms. For generator rooms the ``meta.json`` polygon is the truth; they are
the accuracy goal (<= 3 cm, >= 95 % right count; <= 5 cm with noise).
Then it times the methods on 1M-point rooms.

The baselines share the traced method's floor and ceiling levels and wall band: ``paper`` is the
paper's method as its Figure 3 describes it (outline of the wall points, corner candidates
clustered with DBSCAN at a normalised threshold, corners ordered by angle around the centre;
see :func:`paper_corners`), ``hull`` the convex hull of the wall points with the traced
method's simplification.

``--real SCANS_DIR`` measures only real scans instead (no truth): ``python -m configurator
corners SCAN --approximate`` on every scan of the folder, one line per scan (corners, how the
outline was found, the share of it that wall points back), ending with ``corners, real
scans: ...``; ``--views DIR`` writes each scan's top view with its outline there.

Ends with one line: the traced method on the generator rooms (clean, noisy; mean and worst
corner error), then every method on all rooms (mean error, worst corner, right count, right
order) and the time per 1M points. Errors are given side by side, not as ratios: the traced
error is a fraction of a millimetre to a few millimetres, too small to divide by.
"""
import contextlib
import io
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np
from scipy import ndimage
from scipy.spatial import ConvexHull
from skimage import measure
from sklearn.cluster import DBSCAN

from configurator.corners import CornerDetectionError, CornerParams, detect_corners
from configurator.corners.levels import find_levels
from configurator.corners.simplify import simplify_outline
from configurator.__main__ import main as configurator_main
from synthdet.contracts import read_corners, read_room
from synthdet.info_files import room_sensor
from synthdet.scan_io import read_scan
from tests.room_scans import SHAPES, NoiseModel, make_room
from synthdet.cli import OneLineParser


class Result(NamedTuple):
    """One method on one room (errors in metres; nan if the method found no room)."""

    mean_error: float
    worst_error: float
    right_count: bool
    right_order: bool


def convex_hull_corners(points: np.ndarray, params: CornerParams = CornerParams()) -> np.ndarray:
    """Baseline: convex hull of the wall-band points, simplified like the traced outline."""
    xy = wall_band_xy(points, params)
    hull = xy[ConvexHull(xy).vertices][::-1]  # scipy lists 2D hulls counter-clockwise
    return simplify_outline(
        hull, tolerance=0.05, min_edge=params.min_edge, min_turn=params.min_turn)


def wall_band_xy(points: np.ndarray, params: CornerParams) -> np.ndarray:
    """The plan (x, y) of the points between the floor and ceiling levels, a margin away."""
    floor_z, ceiling_z = find_levels(points[:, :3], params)
    band = (points[:, 2] > floor_z + params.wall_margin) & \
        (points[:, 2] < ceiling_z - params.wall_margin)
    return points[band, :2]


def paper_corners(points: np.ndarray, cell: float = 0.05, eps: float = 0.05) -> np.ndarray:
    """Baseline: the paper's method (Sec. 3.3, Figure 3), as its caption describes it.

    The points projected to the plane and rasterised (``cell``); the outline of the largest
    footprint (holes under furniture filled) and its corner candidates (polygon approximation,
    1.5 cells); the candidates normalised by the room's larger extent and clustered with
    DBSCAN at the normalised threshold ``eps``; one corner per cluster (its mean), ordered
    clockwise by the angle around the centre. Steps (1) to (4) of the figure are not described
    in the text; this reads them as the projection, rasterisation, outline and candidates.
    """
    xy = points[:, :2]
    low = xy.min(axis=0)
    cells = np.floor((xy - low) / cell).astype(np.int64) + 1  # an empty border of one cell
    image = np.zeros(cells.max(axis=0) + 2, dtype=bool)
    image[cells[:, 0], cells[:, 1]] = True
    components, count = ndimage.label(ndimage.binary_closing(image))
    if count == 0:
        raise CornerDetectionError('no walls found')
    largest = np.argmax(np.bincount(components.ravel())[1:]) + 1
    footprint = ndimage.binary_fill_holes(components == largest)
    contours = measure.find_contours(footprint.astype(np.float64), 0.5)
    if not contours:
        raise CornerDetectionError('no outline found')
    contour = max(contours, key=len)
    candidates = measure.approximate_polygon(contour, tolerance=1.5)[:-1]  # closed: drop last
    candidates = (candidates - 0.5) * cell + low  # cell index space to metres
    extent = float(np.ptp(candidates, axis=0).max())
    normalised = (candidates - candidates.min(axis=0)) / extent
    labels = DBSCAN(eps=eps, min_samples=1).fit_predict(normalised)
    corners = np.array([candidates[labels == k].mean(axis=0) for k in np.unique(labels)])
    centre = corners.mean(axis=0)
    angle = np.arctan2(corners[:, 1] - centre[1], corners[:, 0] - centre[0])
    return corners[np.argsort(-angle)]  # clockwise seen from above


def corner_errors(found: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Distance from each true corner to the nearest found corner (metres)."""
    return np.linalg.norm(truth[:, None] - found[None], axis=2).min(axis=1)


def right_order(found: np.ndarray, truth: np.ndarray) -> bool:
    """One found corner per true corner, in the true (clockwise) cyclic order."""
    if len(found) != len(truth):
        return False
    nearest = np.linalg.norm(found[:, None] - truth[None], axis=2).argmin(axis=1)
    return bool(np.array_equal(np.roll(nearest, -int(np.argmin(nearest))), np.arange(len(truth))))


def evaluate(method, points: np.ndarray, truth: np.ndarray) -> Result:
    """Mean and worst corner error, right count, right order (nan errors if detection fails)."""
    try:
        found = method(points)
    except CornerDetectionError:
        return Result(float('nan'), float('nan'), False, False)
    errors = corner_errors(found, truth)
    return Result(
        float(errors.mean()), float(errors.max()),
        len(found) == len(truth), right_order(found, truth))


METHODS = {
    'traced': lambda points: detect_corners(points).corners,
    'paper': paper_corners,
    'hull': convex_hull_corners,
}
LABELS = {
    'traced': 'traced',
    'paper': 'paper (DBSCAN + angle order)',
    'hull': 'convex hull',
}


def generated_rooms(folder: Path):
    """(label, points, true polygon) of every generator room under ``folder``."""
    for meta_path in sorted(folder.rglob('meta.json')):
        meta = read_room(meta_path)
        scan = meta_path.parent / f'{meta_path.parent.name}.txt'
        noise = meta['generator'].get('config', {}).get('scanner', {}).get('range_noise', 0)
        sensor = room_sensor(meta)
        label = (f'generator {meta["room"].get("shape", "?")}' + ('' if sensor == 'paper' else
                                                                  f' {sensor}') +
                 (' noisy' if noise else ''))
        yield label, read_scan(scan), np.array(meta['room']['polygon'], dtype=np.float64)


# the paper's sensor (the other models' rooms: --generated, labelled by their sensor)
_PAPER_SHAPES = {'room': {'shapes': {'box': 0.34, 'L': 0.33, 'U': 0.33}}}
GENERATOR_CONFIGS = {
    'clean': {**_PAPER_SHAPES, 'scanner': {'sensors': {'paper': 1.0}}},
    'noisy': {
        **_PAPER_SHAPES,
        'scanner': {
            'sensors': {'paper': 1.0},
            'range_noise': 0.01,
            'angular_jitter': 0.001,
            'dropout': 0.1
        }
    },
}


def generate_rooms(out: Path, rooms: int, points: int) -> list[Path]:
    """Run the generator for ``rooms`` clean and ``rooms`` noisy rooms under ``out``."""
    folders = []
    for seed, (name, config) in enumerate(GENERATOR_CONFIGS.items(), start=5):
        config_path = out / f'{name}.json'
        config_path.write_text(json.dumps(config))
        command = [
            sys.executable, '-m', 'generator', '--out',
            str(out / name), '--areas', '7', '--rooms-per-area',
            str(rooms), '--points',
            str(points), '--seed',
            str(seed), '--config',
            str(config_path), '--workers', '1', '--quiet'
        ]
        subprocess.run(command, check=True, cwd=Path(__file__).resolve().parents[1])
        folders.append(out / name)
    return folders


def mean_of(runs: list[Result]) -> tuple[float, float, float, float]:
    """Mean error (cm), worst corner (cm), right-count share and right-order share of runs."""
    return (np.nanmean([r.mean_error
                        for r in runs]) * 100, np.nanmax([r.worst_error for r in runs]) * 100,
            float(np.mean([r.right_count
                           for r in runs])), float(np.mean([r.right_order for r in runs])))


def summary(results: dict[str, dict[str, list[Result]]], noisy: bool) -> list[Result]:
    """The traced method's results on the clean or the noisy generator rooms."""
    return [
        run for label, by_method in results.items()
        if label.startswith('generator') and label.endswith('noisy') == noisy
        for run in by_method['traced']
    ]


def time_methods(rooms: int) -> dict[str, float]:
    """Median wall seconds per noisy 1M-point room for each method; prints wall and CPU time."""
    wall = {name: [] for name in METHODS}
    cpu = {name: [] for name in METHODS}
    for seed in range(rooms):
        room = make_room(
            SHAPES[seed % len(SHAPES)], 1_000_000, seed=2000 + seed, noise=NoiseModel())
        for name, method in METHODS.items():
            start, start_cpu = time.perf_counter(), time.process_time()
            method(room.points)
            wall[name].append(time.perf_counter() - start)
            cpu[name].append(time.process_time() - start_cpu)
    seconds = {name: float(np.median(values)) for name, values in wall.items()}
    cpu_seconds = {name: float(np.median(values)) for name, values in cpu.items()}
    print(f'time per 1M-point room (median of {rooms}), wall / CPU: ' +
          ', '.join(f'{LABELS[name]} {seconds[name]:.3f} / {cpu_seconds[name]:.3f} s'
                    for name in METHODS))
    return seconds


def real_scan_outlines(folder: Path, views: Path | None) -> list[tuple[str, int, str, float]]:
    """Scan name, corner count, how the outline was found (traced, partial or approximate)
    and the share of it that wall points back, for every scan file of ``folder`` (not its
    ``.labels.json`` or ``.md`` files), as ``python -m configurator corners SCAN
    --approximate`` finds them; with ``views``, each scan's top view is written there."""
    rows = []
    with tempfile.TemporaryDirectory(prefix='synthdet-bench-corners-') as work:
        for scan in sorted(folder.iterdir()):
            if scan.name.endswith('.labels.json') or scan.suffix == '.md' or scan.is_dir():
                continue
            out = Path(work) / f'{scan.name}.corners.json'
            arguments = ['corners', str(scan), '--out', str(out), '--approximate']
            if views is not None:
                arguments += ['--preview', str(views / f'{scan.name}.png')]
            with contextlib.redirect_stdout(io.StringIO()), \
                    contextlib.redirect_stderr(io.StringIO()) as messages:
                code = configurator_main(arguments)
            if code != 0:
                raise SystemExit(f'{scan}: corners failed: {messages.getvalue().strip()}')
            corners = read_corners(out)
            seen = corners['quality']['walls_seen']
            found = 'approximate' if corners['quality'].get('approximate_floor') else \
                'partial' if seen < CornerParams.min_seen_walls else 'traced'
            rows.append((scan.name, len(corners['corners']), found, seen))
    return rows


def report_real_scans(folder: Path, views: Path | None) -> None:
    """Print :func:`real_scan_outlines` and its headline."""
    if views is not None:
        views.mkdir(parents=True, exist_ok=True)
    rows = real_scan_outlines(folder, views)
    print(f'{"scan":<36} {"corners":>7} {"outline":<12} {"walls back":>10}')
    for name, count, found, seen in rows:
        print(f'{name:<36} {count:>7} {found:<12} {seen:>10.0%}')
    outlined = [count for _, count, found, _ in rows if found != 'approximate']
    partial = sum(found == 'partial' for _, _, found, _ in rows)
    counts = f'{min(outlined)}-{max(outlined)}' if outlined else 'none'
    print(f'corners, real scans: {len(outlined)} of {len(rows)} outlined on their walls '
          f'({partial} partial), {len(rows) - len(outlined)} approximate floors; '
          f'corners per outline {counts}')


def main() -> None:
    parser = OneLineParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--rooms', type=int, default=10, help='rooms per shape and noise')
    parser.add_argument('--points', type=int, default=300_000, help='points per room')
    parser.add_argument(
        '--timing-rooms', type=int, default=3, help='1M-point rooms timed (0: no timing)')
    parser.add_argument(
        '--generated',
        type=Path,
        nargs='*',
        default=[],
        help='folders of python -m generator rooms (meta.json truth)')
    parser.add_argument(
        '--generate',
        type=int,
        default=30,
        help='generator rooms to make, clean and again noisy (0: none)')
    parser.add_argument('--real', type=Path, help='measure the real scans of this folder only')
    parser.add_argument('--views', type=Path, help='with --real: write the top views here')
    args = parser.parse_args()
    if args.real is not None:
        report_real_scans(args.real, args.views)
        return
    workspace = tempfile.TemporaryDirectory(prefix='synthdet-bench-corners-')
    if args.generate:
        args.generated += generate_rooms(Path(workspace.name), args.generate, args.points)

    results: dict[str, dict[str, list[Result]]] = {}
    cases = []
    for noisy in (False, True):
        for shape in SHAPES:
            label = f'{shape} {"noisy" if noisy else "clean"}'
            for seed in range(args.rooms):
                cases.append((label, lambda s=shape, n=noisy, seed=seed: make_room(
                    s, args.points, seed=1000 + seed, noise=NoiseModel() if n else None)))
    for label, make in cases:
        room = make()
        for name, method in METHODS.items():
            results.setdefault(label, {}).setdefault(name, []).append(
                evaluate(method, room.points, room.polygon))
    for folder in args.generated:
        for label, points, truth in generated_rooms(folder):
            for name, method in METHODS.items():
                results.setdefault(label,
                                   {}).setdefault(name,
                                                  []).append(evaluate(method, points, truth))

    print('err = mean corner error (cm); count, order = share of rooms with the right number '
          'of corners, and with them in the right clockwise order')
    print(f'{"rooms":<22}{"n":>4}' + ''.join(f' | {name + " err":>11} {"count":>6} {"order":>6}'
                                             for name in METHODS))
    totals = {name: [] for name in METHODS}
    for label, by_method in results.items():
        row = f'{label:<22}{len(by_method["traced"]):>4}'
        for name in METHODS:
            totals[name] += by_method[name]
            error, _, count, order = mean_of(by_method[name])
            row += f' | {error:>11.2f} {count:>6.0%} {order:>6.0%}'
        print(row)

    timing = ''
    if args.timing_rooms > 0:
        seconds = time_methods(args.timing_rooms)
        timing = '; time per 1M points ' + ', '.join(f'{name} {seconds[name]:.2f} s'
                                                     for name in METHODS)
    generated = []
    for name, noisy in (('clean', False), ('noisy', True)):
        runs = summary(results, noisy)
        if runs:
            error, worst, count, _ = mean_of(runs)
            generated.append(f'{name} {error:.2f} cm (worst corner {worst:.2f} cm) / '
                             f'{count:.0%} right count')
    overall = []
    for name in METHODS:
        error, worst, count, order = mean_of(totals[name])
        overall.append(f'{LABELS[name]} {error:.2f} cm (worst {worst:.1f}) / {count:.0%} / '
                       f'{order:.0%}')
    print(f'corners, generator rooms: traced {", ".join(generated) or "none"}; all rooms '
          f'(mean error, right count, right order): {"; ".join(overall)}{timing}')
    workspace.cleanup()


if __name__ == '__main__':
    main()
