"""Ray casting speed on one generated room with glass: the batched Embree scanner against the
per-ray loops a bpy user would write, on the same scene and rays, and the default sensor models'
scans with each ray engine.

    .venv/bin/python benchmarks/bench_scanner.py [--rays 1000000] [--slow-rays 20000]
        [--scan-points 1000000] [--repeats 3] [--seed 11] [--batch-rays N]

The room is layout seed ``--seed`` of the default configuration (seed 11: a box room whose 3D
printer and one clutter cabinet have glass), scanned as the generator scans it: glass passes
with the default ``glass_transmission`` (0.9), one thread.

Part 1, bare ray casting: every method turns the same numpy rays (origins, unit directions) into
numpy hit distances and triangle (face) indices, the input of labelling:

- ``BVHTree.ray_cast`` loop: one ``mathutils.bvhtree.BVHTree`` of all world triangles, one call
  per ray (the fastest bpy loop);
- ``Object.ray_cast`` loop: the paper's per-object casts, the ray moved into each object's frame
  (vectorised, outside the loop), the nearest hit over the objects kept;
- ``scene.ray_cast`` loop: one call per ray on the scene (the previous baseline).

The scanner calls Embree from a compiled kernel (``generator.embree``: ``rtcIntersect8`` on
packets of 8 rays, hits written into preallocated arrays). Beside it, the engines it replaced:
embreex's ``run`` (the same Embree library and scene mode, one ``rtcIntersect1`` per ray, new
output arrays per call) and Open3D's ``RaycastingScene.cast_rays`` (Embree in robust mode): what
each switch gains, and whether they find the same hits. One warm-up pass on the first 1000
rays, then the median of ``--repeats`` timed passes with the garbage collector off, the passes
going round the methods in turn; the slow
loops (``Object`` and ``scene``) take the first ``--slow-rays`` rays. Each loop's hits are
checked against Embree's. All methods run on one thread (bpy's ray casts are single-threaded);
Embree on all cores is printed beside it.

Part 2, the default sensor models at their defaults (``generator.sensors.scan_room``): the
models the default configuration draws, those with a share above 0 in ``scanner.sensors`` (the
paper's crossing path with aimed object rays, the terrestrial laser scanner, the tablet; the
depth frame has the share 0 and is drawn only by profiles such as ``mixed_rooms``, so it is not
timed; the output names the shares), each a scan of ``--scan-points`` labelled points, with
Embree and with the ``BVHTree`` loop as the ray engine of the same scan code (glass passes
included), one thread each, the median of ``--repeats`` scans going round the engines in turn.
Rays per second count the rays a scan casts (``rays_cast``; its glass passes are extra work
within them). Where the Embree scan's time goes is timed inside it: the first hits of its ray
batches (casting), the glass passes (their casts and bookkeeping), the noise models (range-error
draws made apart from other work: the laser scanner's range errors and mixed pixels, numpy's
1-D normal draws; the tablet draws its range errors in the kernel that keeps its returns, which
counts as rest), the laser scanner's spacing filter (``generator.tls.SpacingFilter``), and the
rest (ray generation, labelling, the final subset); writing the
room's files (``generator.writer.write_room``) is timed after the scan. The physical bound is
the bare Embree cast of exactly the ray batches the scan cast, first hits and glass passes
(recorded in one more scan): "our scan / bare cast" is what is left to win. The scans' process
CPU seconds (medians, summed over the models) are printed too: on a busy machine they leave out
the waits for a core, which wall times include.

The machine's load average (1, 5, 15 minutes) is printed before and after: on a shared machine
the wall times grow with it, the ratios less. The last line gives, one thread each: the rays per
second of the default sensors' scans against the same scans on the ``BVHTree`` loop (over the
three models, and per model), the bare ray casting ratio on the random rays, and our scan / bare
cast.
"""
import argparse
import contextlib
import gc
import os
import shutil
import statistics
import tempfile
import time
from collections import Counter
from pathlib import Path
from typing import Callable, Iterator, Sequence

import bpy
import numpy as np
from mathutils import Vector
from mathutils.bvhtree import BVHTree

from generator import tls
from generator.assets.palette import METAL, SEE_THROUGH
from generator.config import load_config
from generator.embree import first_hits
from generator.layout import catalog_from_library, generate_layout, layout_meta
from generator.pipeline import RunOptions, open_library
from generator.scanner import (
    ScanResult, Scanner, TriangleScene, random_directions, sensor_path, triangles_of_colors)
from generator.scene import COLLECTION, RoomScene, export_triangles
from generator.sensor_common import RoomGeometry, room_geometry
from generator.sensors import label_stray_returns, scan_room
from generator.writer import write_room
from synthdet.contracts import ROOM_FORMAT, SENSOR_MODELS
from synthdet.cli import OneLineParser

Caster = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]
ENGINES = ('embree', 'loop')  # the scans' two ray engines: Embree, the BVHTree loop


def bvhtree_caster(vertices: np.ndarray, triangles: np.ndarray) -> Caster:
    """Per-ray ``BVHTree.ray_cast`` on one tree of the world triangles."""
    tree = BVHTree.FromPolygons(vertices.tolist(), triangles.tolist(), all_triangles=True)

    def cast(origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ray_cast = tree.ray_cast
        distance, face = [], []
        for o, d in zip(origins.tolist(), directions.tolist()):
            _location, _normal, index, t = ray_cast(o, d)
            distance.append(t)
            face.append(index)
        # a miss gives None, which numpy turns into nan
        distance = np.array(distance, dtype=np.float64)
        face = np.array(face, dtype=np.float64)
        return np.nan_to_num(distance, nan=np.inf), np.nan_to_num(face, nan=-1).astype(np.int64)

    return cast


def embreex_caster(vertices: np.ndarray, triangles: np.ndarray) -> Caster:
    """embreex's ``run`` on one scene in Embree's default mode, as the scanner's previous
    ``Scanner.cast`` called it: float32 rays, output arrays of every hit field per call."""
    from embreex.mesh_construction import TriangleMesh
    from embreex.rtcore_scene import EmbreeScene
    scene = EmbreeScene(robust=False)
    TriangleMesh(scene, vertices.astype(np.float32), triangles.astype(np.int32))

    def cast(origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        answer = scene.run(origins.astype(np.float32), directions.astype(np.float32),
                           dists=np.full(len(origins), np.inf, dtype=np.float32), output=1)
        return answer['tfar'], answer['primID']

    return cast


def open3d_caster(vertices: np.ndarray, triangles: np.ndarray) -> Caster:
    """Open3D's ``RaycastingScene.cast_rays`` on one thread (Embree in robust mode), as the
    scanner's first engine called it: an (N, 6) float32 ray array per batch."""
    import open3d as o3d
    scene = o3d.t.geometry.RaycastingScene(nthreads=1)
    scene.add_triangles(
        o3d.core.Tensor(vertices.astype(np.float32)), o3d.core.Tensor(triangles.astype(np.uint32)))

    def cast(origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rays = np.empty((len(origins), 6), dtype=np.float32)
        rays[:, :3] = origins
        rays[:, 3:] = directions
        answer = scene.cast_rays(o3d.core.Tensor.from_numpy(rays), nthreads=1)
        return answer['t_hit'].numpy(), answer['primitive_ids'].numpy()

    return cast


def object_caster(objects: list, face_offsets: np.ndarray) -> Caster:
    """The paper's per-object ``Object.ray_cast``, nearest hit over the objects; the world face
    index is the object's offset plus its face index."""
    inverse = [np.linalg.inv(np.array(obj.matrix_world, dtype=np.float64)) for obj in objects]

    def cast(origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        distance = np.full(len(origins), np.inf)
        face = np.full(len(origins), -1, dtype=np.int64)
        for obj, matrix, offset in zip(objects, inverse, face_offsets):
            local_o = (origins @ matrix[:3, :3].T + matrix[:3, 3]).tolist()
            local_d = (directions @ matrix[:3, :3].T).tolist()  # rigid: lengths kept
            ray_cast = obj.ray_cast
            for i, (o, d) in enumerate(zip(local_o, local_d)):
                hit, location, _normal, index = ray_cast(o, d)
                if hit:
                    t = (location - Vector(o)).length
                    if t < distance[i]:
                        distance[i], face[i] = t, offset + index
        return distance, face

    return cast


def scene_caster(face_offsets: dict[str, int]) -> Caster:
    """Per-ray ``scene.ray_cast`` on the evaluated scene (world frame)."""
    scene = bpy.context.scene
    depsgraph = bpy.context.evaluated_depsgraph_get()

    def cast(origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        distance = np.full(len(origins), np.inf)
        face = np.full(len(origins), -1, dtype=np.int64)
        for i, (o, d) in enumerate(zip(origins.tolist(), directions.tolist())):
            hit, location, _normal, index, obj, _matrix = scene.ray_cast(depsgraph, o, d)
            if hit:
                distance[i] = (location - Vector(o)).length
                face[i] = face_offsets[obj.name] + index
        return distance, face

    return cast


def timed(methods: dict[str, tuple[Caster, int]], origins: np.ndarray, directions: np.ndarray,
          repeats: int) -> dict[str, tuple[int, float, tuple[np.ndarray, np.ndarray]]]:
    """Per method (caster, rays): rays, median seconds of ``repeats`` passes, last result.

    Every method gets one warm-up pass on the first 1000 rays; the timed passes go round the
    methods in turn, so that a change of load on a shared machine falls on all of them. The
    garbage collector is off while timing: the per-ray loops allocate a result tuple per ray,
    and collections over this process's large heap would otherwise slow them down several
    times.
    """
    for cast, _ in methods.values():
        cast(origins[:1000], directions[:1000])
    seconds = {label: [] for label in methods}
    results = {}
    gc.collect()
    gc.disable()
    try:
        for _ in range(repeats):
            for label, (cast, n) in methods.items():
                start = time.perf_counter()
                results[label] = cast(origins[:n], directions[:n])
                seconds[label].append(time.perf_counter() - start)
    finally:
        gc.enable()
    return {
        label: (n, statistics.median(seconds[label]), results[label])
        for label, (_, n) in methods.items()
    }


class BVHTreeScanner(Scanner):
    """The scanner with the per-ray ``BVHTree.ray_cast`` loop as its ray engine: the same ray
    generation, glass passes, noise and labelling around it."""

    def __init__(self, scene: TriangleScene, glass_colors: Sequence, glass_transmission: float):
        super().__init__(scene, 1, glass_colors, glass_transmission)
        self.loops = {
            id(self.full_scene): bvhtree_caster(scene.vertices, scene.triangles),
            id(self.object_scene): bvhtree_caster(scene.vertices,
                                                  scene.triangles[self.object_tri]),
        }

    def _first_hits(self, raycaster, origins: np.ndarray,
                    directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        distance, face = self.loops[id(raycaster)](np.asarray(origins, dtype=np.float32),
                                                   np.asarray(directions, dtype=np.float32))
        return distance.astype(np.float32), face.astype(np.int32).view(np.uint32)


class ProfiledScanner(Scanner):
    """The Embree scanner timing its first hits and glass passes, optionally keeping every ray
    batch it casts (for the bare cast of the same rays)."""

    def __init__(self, scene: TriangleScene, glass_colors: Sequence, glass_transmission: float):
        super().__init__(scene, 1, glass_colors, glass_transmission)
        self.seconds: Counter = Counter()
        self.batches: list | None = None
        self._first_of_cast = False

    def cast(self, raycaster, origins, directions, rng=None):
        start = time.perf_counter()
        self._first_of_cast = True
        answer = super().cast(raycaster, origins, directions, rng)
        self.seconds['cast'] += time.perf_counter() - start
        return answer

    def _first_hits(self, raycaster, origins, directions):
        start = time.perf_counter()
        answer = super()._first_hits(raycaster, origins, directions)
        key = 'first hits' if self._first_of_cast else 'glass casts'
        self.seconds[key] += time.perf_counter() - start
        self._first_of_cast = False
        if self.batches is not None:
            self.batches.append((raycaster, np.array(origins, dtype=np.float32),
                                 np.array(directions, dtype=np.float32)))
        return answer


class TimedRandom:
    """A ``np.random.Generator`` stand-in that adds the time of its range-error draws (1-D
    ``normal`` and ``standard_normal``) to ``seconds['noise']``; the same numbers."""

    def __init__(self, rng: np.random.Generator, seconds: Counter):
        self._rng, self._seconds = rng, seconds

    def __getattr__(self, name: str):
        method = getattr(self._rng, name)
        if name not in ('normal', 'standard_normal'):
            return method

        def timed_draw(*args, **kwargs):
            start = time.perf_counter()
            answer = method(*args, **kwargs)
            if np.ndim(answer) == 1:  # range errors; (N, 3) draws are the angular jitter
                self._seconds['noise'] += time.perf_counter() - start
            return answer

        return timed_draw


@contextlib.contextmanager
def timed_sensor_parts(seconds: Counter) -> Iterator[None]:
    """Time ``generator.tls``' range errors and mixed pixels (as noise) and its spacing filter
    into ``seconds``."""
    range_noise, mixed_pixels, spacing_filter = (tls.add_range_noise, tls.mix_at_depth_edges,
                                                 tls.SpacingFilter)

    def timed_noise(function: Callable) -> Callable:

        def timed_call(*args, **kwargs):
            start = time.perf_counter()
            answer = function(*args, **kwargs)
            seconds['noise'] += time.perf_counter() - start
            return answer

        return timed_call

    class TimedSpacingFilter(spacing_filter):

        def new_returns(self, *args, **kwargs) -> np.ndarray:
            start = time.perf_counter()
            answer = super().new_returns(*args, **kwargs)
            seconds['spacing filter'] += time.perf_counter() - start
            return answer

    tls.add_range_noise = timed_noise(range_noise)
    tls.mix_at_depth_edges = timed_noise(mixed_pixels)
    tls.SpacingFilter = TimedSpacingFilter
    try:
        yield
    finally:
        tls.add_range_noise, tls.mix_at_depth_edges = range_noise, mixed_pixels
        tls.SpacingFilter = spacing_filter


def scan_once(scanner: Scanner, room: RoomGeometry, model: str, points: int, config: dict,
              seconds: Counter) -> tuple[float, ScanResult]:
    """One scan of ``model`` (rng seed 1, garbage collector off): its seconds and result; its
    process CPU seconds are added to ``seconds['cpu']``."""
    rng = TimedRandom(np.random.default_rng(1), seconds)
    gc.collect()
    gc.disable()
    try:
        with timed_sensor_parts(seconds):
            start, cpu = time.perf_counter(), time.process_time()
            scan, _ = scan_room(scanner, room, model, points, 0.5, rng, config, METAL)
            seconds['cpu'] += time.process_time() - cpu
            return time.perf_counter() - start, scan
    finally:
        gc.enable()


def bare_cast(batches: list) -> float:
    """Seconds of Embree's bare first-hit casts of ``batches`` on one thread, with the scan's
    engine (``generator.embree.first_hits``)."""
    start = time.perf_counter()
    for raycaster, origins, directions in batches:
        first_hits(raycaster, origins, directions)
    return time.perf_counter() - start


def default_models(config: dict) -> list[str]:
    """The sensor models the configuration draws (a share above 0), in the contract's order."""
    shares = config['scanner']['sensors']
    return [model for model in SENSOR_MODELS if float(shares.get(model, 0.0)) > 0]


def time_sensor_scans(scene: TriangleScene, room: RoomGeometry, names: list[str], meta: dict,
                      models: list[str], points: int, config: dict, repeats: int,
                      out: Path) -> dict[str, dict]:
    """Per sensor model of ``models``: the Embree and ``BVHTree`` scans (median seconds,
    rays), the Embree scan's parts (median seconds each), its writing time and the bare cast of
    its rays."""
    glass = (SEE_THROUGH, config['glass_transmission'])
    embree, loop = ProfiledScanner(scene, *glass), BVHTreeScanner(scene, *glass)
    results = {}
    for model in models:
        for scanner in (embree, loop):  # warm-up
            scan_once(scanner, room, model, min(points, 10_000), config, Counter())
        runs = {'embree': [], 'loop': [], 'parts': [], 'loop cpu': []}
        for _ in range(repeats):
            embree.seconds = Counter()
            # each scan's result is dropped at once: no live result adds page faults to the next
            runs['embree'].append(scan_once(embree, room, model, points, config, embree.seconds)[0])
            runs['parts'].append(embree.seconds)
            loop_seconds = Counter()
            runs['loop'].append(scan_once(loop, room, model, points, config, loop_seconds)[0])
            runs['loop cpu'].append(loop_seconds['cpu'])
        embree.seconds, embree.batches = Counter(), []
        _, scan = scan_once(embree, room, model, points, config, embree.seconds)
        batches, embree.batches = embree.batches, None
        bare = statistics.median(bare_cast(batches) for _ in range(repeats))
        start = time.perf_counter()
        labels, annotations, _ = label_stray_returns(scan.part, names, scan.stray)
        write_room(out, f'{model}_room', scan.xyz, scan.rgb, labels, annotations, meta)
        writing = time.perf_counter() - start
        shutil.rmtree(out / f'{model}_room')
        parts = {
            key: statistics.median(p[key] for p in runs['parts'])
            for key in ('first hits', 'cast', 'glass casts', 'noise', 'spacing filter')
        }
        results[model] = {
            'rays': scan.rays_cast,
            'cast rays': sum(len(b[1]) for b in batches),
            'embree': statistics.median(runs['embree']),
            'loop': statistics.median(runs['loop']),
            'embree cpu': statistics.median(p['cpu'] for p in runs['parts']),
            'loop cpu': statistics.median(runs['loop cpu']),
            'parts': parts,
            'bare': bare,
            'writing': writing,
        }
    return results


def print_sensor_scans(results: dict[str, dict], shares: dict, points: int,
                       repeats: int) -> float:
    """The per-model table and the time shares of the Embree scans; returns the ratio of the
    rays per second over all models."""
    mix = ', '.join(f'{model} {float(shares.get(model, 0.0)):g}' for model in SENSOR_MODELS)
    print(f'default sensor models (the default configuration\'s mix: {mix}; a model of share 0 '
          f'is not timed), {points:,} labelled points each, glass passes, 1 thread, median of '
          f'{repeats} (rays = the scan\'s rays; with glass passes: cast)')
    print(f'{"model":<8}{"rays":>11}{"cast":>11}{"Embree s":>10}{"rays/s":>13}{"BVHTree s":>11}'
          f'{"rays/s":>12}{"ratio":>7}{"bare s":>8}{"scan/bare":>10}')
    for model, r in results.items():
        print(f'{model:<8}{r["rays"]:>11,}{r["cast rays"]:>11,}{r["embree"]:>10.3f}'
              f'{r["rays"] / r["embree"]:>13,.0f}{r["loop"]:>11.2f}{r["rays"] / r["loop"]:>12,.0f}'
              f'{r["loop"] / r["embree"]:>6.1f}x{r["bare"]:>8.3f}{r["embree"] / r["bare"]:>9.1f}x')
    print('where the Embree scan\'s time goes (seconds, share of the scan; writing after it):')
    print(f'{"model":<8}{"casting":>15}{"glass passes":>15}{"noise":>15}{"spacing filter":>16}'
          f'{"rest":>15}{"writing":>9}')
    for model, r in results.items():
        p = r['parts']
        glass = p['cast'] - p['first hits']
        rest = r['embree'] - p['cast'] - p['noise'] - p['spacing filter']
        cells = [p['first hits'], glass, p['noise'], p['spacing filter'], rest]
        print(f'{model:<8}' + ''.join(f'{v:>8.3f} {v / r["embree"]:>5.0%}' for v in cells[:3]) +
              f'{cells[3]:>9.3f} {cells[3] / r["embree"]:>5.0%}{rest:>8.3f} '
              f'{rest / r["embree"]:>5.0%}{r["writing"]:>9.3f}')
    cpu = {engine: sum(r[f'{engine} cpu'] for r in results.values()) for engine in ENGINES}
    print(f'process CPU seconds of the scans, without the waits for a core on a busy machine '
          f'(median per model, summed): Embree {cpu["embree"]:.2f} s, BVHTree loop '
          f'{cpu["loop"]:.2f} s: {cpu["loop"] / cpu["embree"]:.1f}x rays per CPU second')
    rays = sum(r['rays'] for r in results.values())
    return (rays / sum(r['embree'] for r in results.values())) / (
        rays / sum(r['loop'] for r in results.values()))


def agreement(found: tuple[np.ndarray, np.ndarray], embree: tuple[np.ndarray, np.ndarray]) -> str:
    """Shares of rays where a loop and Embree agree: hit or miss, first-hit distance within
    1 mm, and the same triangle (rays on an edge shared by two triangles may differ)."""
    distance, face = found
    reference = embree[0][:len(distance)].astype(np.float64)
    both = np.isfinite(distance) & np.isfinite(reference)
    same_hit = np.mean(np.isfinite(distance) == np.isfinite(reference))
    same_t = np.mean(np.abs(distance[both] - reference[both]) < 1e-3)
    same_face = np.mean(face[both] == embree[1][:len(distance)][both])
    return f'hit/miss {same_hit:.2%}, |dt| < 1 mm {same_t:.2%}, triangle {same_face:.2%}'


def bare_cast_methods(triangles: TriangleScene, objects: list, offsets: np.ndarray, rays: int,
                      slow_rays: int) -> dict[str, tuple[Caster, int]]:
    """The ray casters compared on bare rays (label -> caster, rays to cast): Embree on one
    thread and on all, the previous engines and bpy's loops (``objects``: the bpy objects in
    export order, ``offsets``: their first triangles)."""
    embree = {threads: Scanner(triangles, threads=threads) for threads in (1, 0)}
    methods = {
        f'Embree Scanner.cast, {threads or os.cpu_count()} thread(s)':
        (lambda o, d, s=scanner: s.cast(s.full_scene, o, d), rays)
        for threads, scanner in embree.items()
    }
    methods['embreex run (previous engine)'] = (embreex_caster(triangles.vertices,
                                                               triangles.triangles), rays)
    methods['Open3D cast_rays (first engine)'] = (open3d_caster(triangles.vertices,
                                                                triangles.triangles), rays)
    methods['bpy BVHTree.ray_cast loop'] = (bvhtree_caster(triangles.vertices,
                                                           triangles.triangles), rays)
    methods['bpy Object.ray_cast loop (per object)'] = (object_caster(objects,
                                                                      offsets), slow_rays)
    face_offsets = dict(zip((o.name for o in objects), offsets.tolist()))
    methods['bpy scene.ray_cast loop'] = (scene_caster(face_offsets), slow_rays)
    return methods


def print_bare_casts(results: dict[str, tuple], rays: int) -> tuple[str, float]:
    """The table of the bare casts (rays per second, agreement with Embree); returns the
    fastest bpy loop and Embree's (one thread) ratio of rays per second to it."""
    reference = results['Embree Scanner.cast, 1 thread(s)'][2]
    print(f'bare ray casting, {rays:,} uniform rays from the paper\'s path:')
    print(f'{"method":<42}{"rays":>9}{"seconds":>9}{"rays/s":>13}  agreement with Embree')
    rate = {}
    for label, (n, seconds, found) in results.items():
        rate[label] = n / seconds
        check = '' if label.startswith('Embree') else agreement(found, reference)
        print(f'{label:<42}{n:>9}{seconds:>9.3f}{rate[label]:>13,.0f}  {check}')
    fastest = max((label for label in rate if label.startswith('bpy')), key=rate.get)
    return fastest, rate['Embree Scanner.cast, 1 thread(s)'] / rate[fastest]


def parse_args() -> argparse.Namespace:
    """The benchmark's command line."""
    parser = OneLineParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--rays', type=int, default=1_000_000, help='rays for BVHTree and Embree')
    parser.add_argument(
        '--slow-rays', type=int, default=20_000, help='rays for Object and scene ray_cast')
    parser.add_argument('--repeats', type=int, default=3, help='timed passes and scans (median)')
    parser.add_argument('--scan-points', type=int, default=1_000_000)
    parser.add_argument('--asset-cache', type=Path, default=None)
    parser.add_argument('--seed', type=int, default=11, help='layout seed of the room')
    parser.add_argument(
        '--batch-rays', type=int, default=None, help='rays per cast (default: the generator\'s)')
    return parser.parse_args()


def main() -> None:
    """Time the bare casts and every default sensor's scan in one generated room."""
    args = parse_args()
    print('load average (1, 5, 15 min) before: ' + ', '.join(f'{v:.2f}' for v in os.getloadavg()))

    for obj in list(bpy.data.objects):  # bpy's start-up cube, camera and light
        bpy.data.objects.remove(obj, do_unlink=True)
    config = load_config()
    if args.batch_rays:
        config['scanner']['batch_rays'] = args.batch_rays
    workspace = tempfile.TemporaryDirectory(prefix='synthdet-bench-scanner-')  # removed at exit
    cache = args.asset_cache or Path(workspace.name) / 'assets'
    options = RunOptions(
        out='', points=1, object_ratio=0.5, seed=0, config=config, asset_cache=str(cache))
    library = open_library(options)
    by_name = {i.name: i for c in library.classes() for i in library.instances(c)}
    layout = generate_layout(
        np.random.default_rng(args.seed), catalog_from_library(library), config)
    room = RoomScene(lambda cls, name: by_name[name].mesh_arrays())
    room.build(layout, np.random.default_rng(0))
    triangles, names, classes = export_triangles()
    # the bpy objects in export order: their faces are the TriangleScene's triangles, in order
    objects = sorted(
        bpy.data.collections[COLLECTION].objects, key=lambda o: o['synthdet_instance'])
    offsets = np.cumsum([0] + [len(o.data.polygons) for o in objects])[:-1]
    glass = triangles_of_colors(triangles, SEE_THROUGH)
    glass_classes = sorted({classes[p] for p in triangles.part[glass]})
    print(f'scene: {layout.shape} room {np.ptp(layout.polygon, axis=0).round(2).tolist()} m, '
          f'{len(objects)} objects, {len(triangles.triangles)} triangles ({int(glass.sum())} of '
          f'glass, on {", ".join(glass_classes) or "nothing"}); one warm-up pass, median of '
          f'{args.repeats}')

    rng = np.random.default_rng(0)
    path, _ = sensor_path(layout.polygon, layout.height, rng)
    origins = path[np.arange(args.rays) % len(path)]
    directions = random_directions(rng, args.rays)

    methods = bare_cast_methods(triangles, objects, offsets, args.rays, args.slow_rays)
    results = timed(methods, origins, directions, args.repeats)
    fastest, bare_ratio = print_bare_casts(results, args.rays)

    geometry = room_geometry(layout.polygon, layout.height, layout.bays, triangles, classes)
    meta = {'format': ROOM_FORMAT, **layout_meta(layout)}
    scans = time_sensor_scans(triangles, geometry, names, meta, default_models(config),
                              args.scan_points, config['scanner'], args.repeats,
                              Path(workspace.name))
    scan_ratio = print_sensor_scans(scans, config['scanner']['sensors'], args.scan_points,
                                    args.repeats)
    print('load average (1, 5, 15 min) after: ' + ', '.join(f'{v:.2f}' for v in os.getloadavg()))
    per_model = ', '.join(f'{m} {r["loop"] / r["embree"]:.1f}x' for m, r in scans.items())
    bound = sum(r['embree'] for r in scans.values()) / sum(r['bare'] for r in scans.values())
    print(f'scanner vs fastest bpy loop ({fastest}), 1 thread each, median of {args.repeats}: '
          f'default sensor scans with glass {scan_ratio:.1f}x rays/s ({per_model}); bare ray '
          f'casting {bare_ratio:.1f}x; our scan / bare Embree cast {bound:.1f}x')


if __name__ == '__main__':
    main()
