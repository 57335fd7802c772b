"""Generation runs: room tasks, per-room seeds, workers, resume and sharding.

A run is a list of rooms ``(area, index)``. Each room's seed is derived from
``(seed, area, index)`` only, so the files do not depend on the worker count, the shard or the
order of work. Finished rooms are skipped (a room folder appears only complete, by rename),
temporary folders of interrupted rooms are removed, so a killed run restarted completes the areas
without duplicates.
"""
import os
import sys
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import numpy as np

ROOM_PREFIX = 'factory'
META_VERSION = 1


@dataclass(frozen=True)
class RoomTask:
    """One room to generate."""

    area: int
    index: int  # 1-based within its area
    seed: int

    @property
    def name(self) -> str:
        return f'{ROOM_PREFIX}_{self.index}'


@dataclass
class RunOptions:
    """Everything a worker needs to generate rooms (picklable for 'spawn' workers)."""

    out: str
    points: int
    object_ratio: float
    seed: int
    config: dict[str, Any]
    library: str | None = None  # directory of user <class>.blend files, or None
    asset_cache: str | None = None  # cache of the procedural library
    asset_seed: int = 0
    ply: bool = False
    preview: bool = False
    save_blend: bool = False
    threads: int = 1


def room_seed(seed: int, area: int, index: int) -> int:
    """The 63-bit seed of room ``index`` of ``area`` for run seed ``seed``."""
    state = np.random.SeedSequence([seed, area, index]).generate_state(2, dtype=np.uint32)
    return int((int(state[0]) << 31) ^ int(state[1])) & (2**63 - 1)


def plan_tasks(areas: list[int], rooms_per_area: int, seed: int,
               shard: tuple[int, int] = (1, 1)) -> list[RoomTask]:
    """All rooms of the run in a fixed order; shard K/N (1-based) keeps every N-th from K."""
    k, n = shard
    tasks = [
        RoomTask(area, index, room_seed(seed, area, index)) for area in areas
        for index in range(1, rooms_per_area + 1)
    ]
    return tasks[k - 1::n]


def default_asset_cache() -> Path:
    base = os.environ.get('XDG_CACHE_HOME') or os.path.join(os.path.expanduser('~'), '.cache')
    return Path(base) / 'synthdet' / 'assets'


def open_library(options: RunOptions):
    """Load the user's library directory, or build/load the cached procedural library."""
    from generator.assets import default_library, load_library
    if options.library:
        return load_library(Path(options.library))
    cache = Path(options.asset_cache) if options.asset_cache else default_asset_cache()
    return default_library(cache, seed=options.asset_seed)


class RoomGenerator:
    """Per-process state: asset library, layout catalog and the bpy room scene."""

    def __init__(self, options: RunOptions):
        import bpy  # noqa: F401  (bpy before open3d: both ship libtbb, the first one wins)
        from generator.layout import catalog_from_library
        from generator.scene import RoomScene
        self.options = options
        self.library = open_library(options)
        self.catalog = catalog_from_library(self.library)
        by_name = {
            (inst.cls, inst.name): inst
            for cls in self.library.classes()
            for inst in self.library.instances(cls)
        }
        self.scene = RoomScene(lambda cls, name: by_name[(cls, name)].mesh_arrays())

    def generate(self, task: RoomTask) -> tuple[RoomTask, str, float]:
        """Generate and write one room unless it exists; return (task, status, seconds)."""
        from generator.appearance import apply_appearance, draw_appearance
        from generator.layout import generate_layout, layout_meta
        from generator.assets.palette import METAL, SEE_THROUGH
        from generator.scanner import Scanner
        from generator.scene import export_triangles
        from generator.sensor_common import room_geometry
        from generator.sensors import choose_sensor, label_stray_returns, scan_room
        from generator.writer import TMP_PREFIX, clean_stale, write_room
        start = time.perf_counter()
        options = self.options
        area_dir = Path(options.out) / f'Area_{task.area}'
        if (area_dir / task.name).exists():
            return task, 'skipped', 0.0
        clean_stale(area_dir, task.name)
        rng_layout, rng_scene, rng_scan = (
            np.random.default_rng([task.seed, stream]) for stream in range(3))
        layout = generate_layout(rng_layout, self.catalog, options.config)
        self.scene.build(layout, rng_scene)
        extra = {}
        if options.save_blend:
            area_dir.mkdir(parents=True, exist_ok=True)
            blend = area_dir / f'{TMP_PREFIX}{task.name}.{os.getpid()}.blend'
            self.scene.save(blend)
            extra[f'{task.name}.blend'] = blend
        triangles, names, classes = export_triangles()
        scan_cfg = options.config['scanner']
        # the sensor model is drawn from its own stream (4; 3 is the appearance's): the scan
        # stream stays the paper sensor's
        model = choose_sensor(scan_cfg['sensors'], np.random.default_rng([task.seed, 4]))
        room = room_geometry(layout.polygon, layout.height, layout.bays, triangles, classes)
        scanner = Scanner(triangles, options.threads, SEE_THROUGH, scan_cfg['glass_transmission'])
        scan, sensor = scan_room(scanner, room, model, options.points, options.object_ratio,
                                 rng_scan, scan_cfg, METAL)
        # a stream of its own: appearance settings change neither the layout nor the scan
        appearance = draw_appearance(
            np.random.default_rng([task.seed, 3]), options.config['appearance'], len(names))
        rgb = apply_appearance(appearance, scan, triangles)
        labels, names, stray_instance = label_stray_returns(scan.part, names, scan.stray)
        if stray_instance:
            sensor['stray_instance'] = stray_instance
            sensor['stray_points'] = int(scan.stray.sum())
        meta = _room_meta(options, task, sensor, (scan.object_points, scan.rays_cast),
                          appearance.meta(), layout_meta(layout))
        write_room(
            area_dir,
            task.name,
            scan.xyz,
            rgb,
            labels,
            names,
            meta,
            ply=options.ply,
            preview=options.preview,
            extra_files=extra)
        return task, 'written', time.perf_counter() - start


def _room_meta(options: RunOptions, task: RoomTask, sensor: dict[str, Any],
               counts: tuple[int, int], appearance: dict[str, Any],
               layout: dict[str, Any]) -> dict[str, Any]:
    """The room's meta.json: its seed, the run's settings, the sensor's record (the paper
    sensor's path and height as fields of their own) with the scan's ``counts`` (object
    points, rays cast), the appearance and the ``layout``."""
    from synthdet.contracts import ROOM_FORMAT

    paper = {} if sensor['model'] != 'paper' else {
        'sensor_path': sensor.pop('path'),
        'sensor_height': sensor.pop('height')
    }
    return {
        'format': ROOM_FORMAT,
        'seed': task.seed,
        'generator': {
            'points': options.points,
            'object_ratio': options.object_ratio,
            'run_seed': options.seed,
            'area': task.area,
            'room_index': task.index,
            'asset_seed': options.asset_seed,
            'library': 'procedural' if not options.library else 'user',
            'version': META_VERSION,
            'object_points': int(counts[0]),
            'rays': int(counts[1]),
            'sensor': sensor,
            **paper,
            'appearance': appearance,
            'config': options.config
        },
        **layout
    }


_WORKER: RoomGenerator | None = None
_WORKER_ERROR: BaseException | None = None


def _init_worker(options: RunOptions, parent_pid: int) -> None:
    # an exception here would make the pool restart the worker forever: keep it for the tasks
    global _WORKER, _WORKER_ERROR
    from synthdet.processes import die_with_parent
    die_with_parent(parent_pid)  # nothing is generated or published for a dead parent
    try:
        _WORKER = RoomGenerator(options)
    except Exception as err:  # reported by the first task, in the parent process
        _WORKER_ERROR = err


def _run_task(task: RoomTask) -> tuple[RoomTask, str, float]:
    if _WORKER is None:
        raise RuntimeError(
            f'generator worker failed to start: {_WORKER_ERROR!r}') from _WORKER_ERROR
    return _WORKER.generate(task)


@contextmanager
def _spawn_safe_sys_path() -> Iterator[None]:
    """Hide bpy's own script folders from sys.path while spawning workers.

    Importing bpy adds ``.../bpy/<version>/scripts/modules`` to sys.path; a 'spawn' child inherits
    that path and would then import the inner pure-Python ``bpy`` package instead of the module.
    """
    saved = list(sys.path)
    sys.path[:] = [p for p in sys.path if not {'bpy', 'scripts'} <= set(Path(p).parts)]
    try:
        yield
    finally:
        sys.path[:] = saved


def run(tasks: list[RoomTask],
        options: RunOptions,
        workers: int = 1,
        progress: bool = True) -> Iterator[tuple[RoomTask, str, float]]:
    """Generate ``tasks`` with ``workers`` processes ('spawn'); yield results as rooms finish."""
    from tqdm import tqdm
    from generator.writer import remove_orphaned_tmp
    for area in sorted({t.area for t in tasks}):  # leftovers of killed runs
        remove_orphaned_tmp(Path(options.out) / f'Area_{area}')
    todo = [t for t in tasks if not (Path(options.out) / f'Area_{t.area}' / t.name).exists()]
    bar = tqdm(
        total=len(tasks),
        initial=len(tasks) - len(todo),
        unit='room',
        disable=not progress,
        desc='rooms')
    # build (or check) the asset library once, before workers race to the cache
    open_library(options)
    if workers <= 1 or len(todo) <= 1:
        generator = RoomGenerator(options)
        for task in todo:
            result = generator.generate(task)
            bar.update(1)
            yield result
    else:
        import multiprocessing
        context = multiprocessing.get_context('spawn')
        with _spawn_safe_sys_path():
            pool = context.Pool(workers, initializer=_init_worker, initargs=(options, os.getpid()))
        with pool:
            for result in pool.imap_unordered(_run_task, todo):
                bar.update(1)
                yield result
    bar.close()
