"""FreeCAD documents from many detections: time per detection at two or more sizes.

    .venv/bin/python benchmarks/bench_freecad.py [--sizes 1000 10000 ...] [--freecadcmd freecadcmd]

For each size it writes synthetic predictions (the classes table, chair, sofa, bookcase,
3dprinter and forklift in turn, with random sizes and yaws, one per square-metre cell of a
square room, so that none overlap or merge) and, in one ``freecadcmd`` process per size, times
the build (``document.import_detections``: arrangement, parametric models, recompute) and the
save (``macro.save_atomically``: the FCStd, its GUI document and the read-back check), in wall
and CPU seconds of the FreeCAD process (the CPU seconds vary less with the machine's load).
It also counts the document's objects per detection. One row per size, in increasing order.

Ends with one line: the largest size's wall seconds (build, save) and milliseconds per
detection, then the ratio of the per-detection wall times of the largest and the smallest size
(about 1.0: the time grows linearly with the detections; 10x the size and 3x: a step that grows
with the square), for the whole run, the build and the save, and that ratio of the CPU times.
"""
import json
import math
import os
import random
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

from synthdet.cli import OneLineParser

REPO = Path(__file__).resolve().parents[1]
CLASSES = ('table', 'chair', 'sofa', 'bookcase', '3dprinter', 'forklift')

# Runs inside FreeCAD: build and save one document, report the times as JSON.
TIMING_SCRIPT = textwrap.dedent('''\
    import json, os, sys, time
    params = json.load(open(os.environ['SYNTHDET_BENCH_PARAMS'], encoding='utf-8'))
    sys.path.insert(0, params['package_dir'])
    sys.path.append(params['repo'])
    import FreeCAD as App
    from synthdet_freecad import appearance, document, macro, schema

    predictions = schema.read_predictions(params['predictions'])
    corners = schema.read_corners(params['corners'])
    doc = App.newDocument('Bench')
    look = appearance.Look()
    times = [(time.perf_counter(), time.process_time())]
    document.import_detections(doc, predictions, corners, None, 0.0, 0.1, look)
    times.append((time.perf_counter(), time.process_time()))
    macro.save_atomically(doc, params['out'], look)
    times.append((time.perf_counter(), time.process_time()))
    report = {'objects': len(doc.Objects),
              'build': [times[1][k] - times[0][k] for k in (0, 1)],
              'save': [times[2][k] - times[1][k] for k in (0, 1)]}
    with open(params['report'], 'w', encoding='utf-8') as stream:
        json.dump(report, stream)
''')


def write_inputs(folder: Path, count: int, seed: int = 0) -> tuple[Path, Path]:
    """Predictions of ``count`` detections in a square room, and its corners."""
    rng = random.Random(seed)
    side = math.isqrt(count) + 2
    cells = rng.sample(range(side * side), count)
    detections = [{
        'class': CLASSES[index % len(CLASSES)],
        'score': round(rng.uniform(0.5, 1.0), 3),
        'center': [cell % side + 0.5, cell // side + 0.5, 0.4],
        'size': [round(rng.uniform(0.3, 0.8), 3),
                 round(rng.uniform(0.3, 0.6), 3),
                 round(rng.uniform(0.5, 1.2), 3)],
        'yaw': rng.choice([0.0, round(rng.uniform(-math.pi, math.pi), 4)]),
    } for index, cell in enumerate(cells)]
    predictions = folder / f'{count}.pred.json'
    predictions.write_text(json.dumps({'format': 'synthdet.predictions/1', 'scan': 'bench.txt',
                                       'model': 'bench', 'detections': detections}),
                           encoding='utf-8')
    corners = folder / f'{count}.corners.json'
    corners.write_text(json.dumps({'format': 'synthdet.corners/1', 'scan': 'bench.txt',
                                   'corners': [[0, 0], [0, side], [side, side], [side, 0]],
                                   'floor_z': 0.0, 'ceiling_z': 2.8, 'quality': {}}),
                       encoding='utf-8')
    return predictions, corners


def time_document(folder: Path, count: int, freecadcmd: str) -> dict:
    """Build and save a document of ``count`` detections in FreeCAD; returns its times."""
    predictions, corners = write_inputs(folder, count)
    script = folder / 'time_document.py'
    script.write_text(TIMING_SCRIPT, encoding='utf-8')
    report = folder / f'{count}.report.json'
    params = folder / f'{count}.params.json'
    params.write_text(json.dumps({
        'package_dir': str(REPO / 'configurator' / 'freecad'), 'repo': str(REPO),
        'predictions': str(predictions), 'corners': str(corners),
        'out': str(folder / f'{count}.FCStd'), 'report': str(report)}), encoding='utf-8')
    done = subprocess.run([freecadcmd, str(script)], cwd=folder,
                          env=dict(os.environ, SYNTHDET_BENCH_PARAMS=str(params)),
                          capture_output=True, text=True, errors='replace')
    if not report.is_file():  # freecadcmd exits 0 when its script raises
        raise RuntimeError(f'FreeCAD wrote no timings for {count} detections:\n'
                           f'{(done.stdout + done.stderr)[-3000:]}')
    return json.loads(report.read_text(encoding='utf-8'))


def main() -> int:
    parser = OneLineParser(description=__doc__.split('\n')[0])
    parser.add_argument('--sizes', type=int, nargs='+', default=[1000, 10000],
                        help='two or more detection counts (default 1000 10000)')
    parser.add_argument('--freecadcmd', default='freecadcmd')
    args = parser.parse_args()
    sizes = sorted(set(args.sizes))
    if len(sizes) < 2 or sizes[0] < 1:
        parser.error('--sizes: two or more different positive counts')
    small, large = sizes[0], sizes[-1]
    print(f'load average before: {" ".join(f"{v:.2f}" for v in os.getloadavg())} '
          f'({os.cpu_count()} cores)')
    print(f'{"detections":>10} {"objects":>8} {"build s":>8} {"save s":>8} {"ms each":>8} '
          f'{"build cpu s":>11} {"save cpu s":>10} {"cpu ms each":>11}')
    runs = {}
    with tempfile.TemporaryDirectory(prefix='synthdet-bench-freecad-') as work:
        for count in sizes:
            run = runs[count] = time_document(Path(work), count, args.freecadcmd)
            wall = (run['build'][0] + run['save'][0]) / count * 1000.0
            cpu = (run['build'][1] + run['save'][1]) / count * 1000.0
            print(f'{count:>10,} {run["objects"] / count:>8.1f} {run["build"][0]:>8.1f} '
                  f'{run["save"][0]:>8.1f} {wall:>8.2f} {run["build"][1]:>11.1f} '
                  f'{run["save"][1]:>10.1f} {cpu:>11.2f}', flush=True)
    print(f'load average after: {" ".join(f"{v:.2f}" for v in os.getloadavg())}')

    def per_detection(count: int, *steps: str, clock: int = 0) -> float:
        return sum(runs[count][step][clock] for step in steps) / count

    def ratio(*steps: str, clock: int = 0) -> float:
        larger = per_detection(large, *steps, clock=clock)
        return larger / per_detection(small, *steps, clock=clock)

    build, save = runs[large]['build'][0], runs[large]['save'][0]
    print(f'freecad documents: {large:,} detections {build + save:.1f} s (build {build:.1f} s, '
          f'save {save:.1f} s), {per_detection(large, "build", "save") * 1000:.2f} ms each; '
          f'per-detection time at {large:,} / at {small:,}: {ratio("build", "save"):.2f}x '
          f'(build {ratio("build"):.2f}x, save {ratio("save"):.2f}x; CPU time '
          f'{ratio("build", "save", clock=1):.2f}x)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
