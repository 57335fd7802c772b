"""Ray casting speed on one generated room: the batched Embree scanner (``Scanner.cast``, embreex
``EmbreeScene``) against the per-ray loops a bpy user would write, on the same scene and rays.

    .venv/bin/python benchmarks/bench_scanner.py [--rays 1000000] [--slow-rays 20000]

Every method turns the same numpy rays (origins, unit directions) into numpy hit distances and
triangle (face) indices, the input of labelling:

- ``BVHTree.ray_cast`` loop: one ``mathutils.bvhtree.BVHTree`` of all world triangles, one call
  per ray (the fastest bpy loop);
- ``Object.ray_cast`` loop: the paper's per-object casts, the ray moved into each object's frame
  (vectorised, outside the loop), the nearest hit over the objects kept;
- ``scene.ray_cast`` loop: one call per ray on the scene (the previous baseline).

Beside them, Open3D's ``RaycastingScene.cast_rays`` (Embree in robust mode, the scanner's
previous engine), called as the previous ``Scanner.cast`` did: what the switch to embreex gains,
and whether the two Embree modes find the same hits.

Equal treatment: one warm-up pass on the first 1000 rays, then the median of ``--repeats`` timed
passes with the garbage collector off, the passes going round the methods in turn; the slow
loops (``Object`` and ``scene``) take the first ``--slow-rays`` rays. Each loop's hits are
checked against Embree's. All methods run on one thread (bpy's ray casts are single-threaded);
Embree on all cores is printed beside it.

Then full 1M-point scans (``Scanner.scan``: ray generation, casting, labelling, colours) with
Embree (one thread, all cores) and with the ``BVHTree`` loop as the ray engine in the same
scan code, with the share of the time spent casting. The last line gives the one-thread ratios
against the fastest bpy loop (ray casting, the headline, and the full scan), the all-core
ratios beside them.
"""
import argparse
import gc
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable

import bpy
import numpy as np
from mathutils import Vector
from mathutils.bvhtree import BVHTree

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's generator

from generator.config import load_config  # noqa: E402
from generator.layout import catalog_from_library, generate_layout  # noqa: E402
from generator.pipeline import RunOptions, open_library  # noqa: E402
from generator.scanner import (  # noqa: E402
    Scanner, TriangleScene, random_directions, sensor_path)
from generator.scene import COLLECTION, RoomScene, export_triangles  # noqa: E402

Caster = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


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


def open3d_caster(vertices: np.ndarray, triangles: np.ndarray) -> Caster:
    """Open3D's ``RaycastingScene.cast_rays`` on one thread (Embree in robust mode), as the
    scanner's previous ``Scanner.cast`` called it: an (N, 6) float32 ray array per batch."""
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
    """The scanner's own scan scheme with the per-ray ``BVHTree.ray_cast`` loop as ray engine."""

    def __init__(self, scene: TriangleScene):
        super().__init__(scene, threads=1)
        self.loops = {
            id(self.full_scene): bvhtree_caster(scene.vertices, scene.triangles),
            id(self.object_scene): bvhtree_caster(scene.vertices,
                                                  scene.triangles[self.object_tri]),
        }

    def cast(self, raycaster, origins: np.ndarray,
             directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        distance, face = self.loops[id(raycaster)](origins, directions)
        return distance.astype(np.float32), face


def time_scans(scanners: dict[str, Scanner], path: np.ndarray, points: int, config: dict,
               repeats: int) -> dict[str, tuple[float, float, int]]:
    """Per scanner: median seconds of a full scan, the share of it in ``cast``, rays cast.

    One warm-up scan of 10,000 points each; the timed scans go round the scanners in turn.
    """
    seconds = {label: [] for label in scanners}
    cast_seconds = {label: [] for label in scanners}
    rays = {}
    for scanner in scanners.values():
        scanner.scan(path, 10_000, 0.5, np.random.default_rng(1), config)
    for _ in range(repeats):
        for label, scanner in scanners.items():
            in_cast = []

            def timed_cast(*cast_args, original=type(scanner).cast, scanner=scanner):
                start = time.perf_counter()
                answer = original(scanner, *cast_args)
                in_cast.append(time.perf_counter() - start)
                return answer

            scanner.cast = timed_cast
            gc.collect()
            gc.disable()
            try:
                start = time.perf_counter()
                scan = scanner.scan(path, points, 0.5, np.random.default_rng(1), config)
                seconds[label].append(time.perf_counter() - start)
            finally:
                gc.enable()
                del scanner.cast
            cast_seconds[label].append(sum(in_cast))
            rays[label] = scan.rays_cast
    return {
        label: (statistics.median(seconds[label]),
                statistics.median(np.divide(cast_seconds[label], seconds[label])), rays[label])
        for label in scanners
    }


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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--rays', type=int, default=1_000_000, help='rays for BVHTree and Embree')
    parser.add_argument(
        '--slow-rays', type=int, default=20_000, help='rays for Object and scene ray_cast')
    parser.add_argument('--repeats', type=int, default=5, help='timed passes (median)')
    parser.add_argument('--scan-points', type=int, default=1_000_000)
    parser.add_argument('--scan-repeats', type=int, default=3, help='timed full scans (median)')
    parser.add_argument('--asset-cache', type=Path, default=None)
    parser.add_argument('--seed', type=int, default=3)
    args = parser.parse_args()

    for obj in list(bpy.data.objects):  # bpy's start-up cube, camera and light
        bpy.data.objects.remove(obj, do_unlink=True)
    config = load_config()
    workspace = tempfile.TemporaryDirectory(prefix='synthdet-bench-assets-')  # removed at exit
    cache = args.asset_cache or Path(workspace.name)
    options = RunOptions(
        out='', points=1, object_ratio=0.5, seed=0, config=config, asset_cache=str(cache))
    library = open_library(options)
    by_name = {i.name: i for c in library.classes() for i in library.instances(c)}
    layout = generate_layout(
        np.random.default_rng(args.seed), catalog_from_library(library), config)
    room = RoomScene(lambda cls, name: by_name[name].mesh_arrays())
    room.build(layout, np.random.default_rng(0))
    triangles, names, _ = export_triangles()
    # the bpy objects in export order: their faces are the TriangleScene's triangles, in order
    objects = sorted(
        bpy.data.collections[COLLECTION].objects, key=lambda o: o['synthdet_instance'])
    offsets = np.cumsum([0] + [len(o.data.polygons) for o in objects])[:-1]
    print(f'scene: {layout.shape} room {np.ptp(layout.polygon, axis=0).round(2).tolist()} m, '
          f'{len(objects)} objects, {len(triangles.triangles)} triangles; one warm-up pass, '
          f'median of {args.repeats}')

    rng = np.random.default_rng(0)
    path, _ = sensor_path(layout.polygon, layout.height, rng)
    origins = path[np.arange(args.rays) % len(path)]
    directions = random_directions(rng, args.rays)

    embree = {threads: Scanner(triangles, threads=threads) for threads in (1, 0)}
    methods = {
        f'Embree Scanner.cast, {threads or os.cpu_count()} thread(s)':
        (lambda o, d, s=scanner: s.cast(s.full_scene, o, d), args.rays)
        for threads, scanner in embree.items()
    }
    methods['Open3D cast_rays (previous engine)'] = (open3d_caster(triangles.vertices,
                                                                   triangles.triangles), args.rays)
    methods['bpy BVHTree.ray_cast loop'] = (bvhtree_caster(triangles.vertices,
                                                           triangles.triangles), args.rays)
    methods['bpy Object.ray_cast loop (per object)'] = (object_caster(objects,
                                                                      offsets), args.slow_rays)
    face_offsets = dict(zip((o.name for o in objects), offsets.tolist()))
    methods['bpy scene.ray_cast loop'] = (scene_caster(face_offsets), args.slow_rays)
    results = timed(methods, origins, directions, args.repeats)

    reference = results['Embree Scanner.cast, 1 thread(s)'][2]
    print(f'{"method":<42}{"rays":>9}{"seconds":>9}{"rays/s":>13}  agreement with Embree')
    rate = {}
    for label, (n, seconds, found) in results.items():
        rate[label] = n / seconds
        check = '' if label.startswith('Embree') else agreement(found, reference)
        print(f'{label:<42}{n:>9}{seconds:>9.3f}{rate[label]:>13,.0f}  {check}')

    scanners = {
        f'Embree, {threads or os.cpu_count()} thread(s)': scanner
        for threads, scanner in embree.items()
    }
    scanners['bpy BVHTree.ray_cast loop'] = BVHTreeScanner(triangles)
    scans = time_scans(scanners, path, args.scan_points, config['scanner'], args.scan_repeats)
    print(f'full scan of {args.scan_points:,} labelled points (Scanner.scan, median of '
          f'{args.scan_repeats}), ray engine:')
    for label, (seconds, cast_share, rays) in scans.items():
        print(f'  {label:<40}{seconds:>7.2f} s {args.scan_points / seconds:>11,.0f} points/s, '
              f'{rays:,} rays, ray casting {cast_share:.0%} of the time')

    fastest = max((label for label in rate if label.startswith('bpy')), key=rate.get)
    one = rate['Embree Scanner.cast, 1 thread(s)'] / rate[fastest]
    every = rate[f'Embree Scanner.cast, {os.cpu_count()} thread(s)'] / rate[fastest]
    bvh_scan = scans['bpy BVHTree.ray_cast loop'][0]
    print(f'scan speedup vs fastest bpy loop ({fastest}), 1 thread each: ray casting {one:.1f}x '
          f'(Embree on {os.cpu_count()} threads: {every:.1f}x); full scan '
          f'{bvh_scan / scans["Embree, 1 thread(s)"][0]:.1f}x '
          f'({bvh_scan / scans[f"Embree, {os.cpu_count()} thread(s)"][0]:.1f}x)')


if __name__ == '__main__':
    main()
