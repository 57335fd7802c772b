"""The RGB-D reconstruction sensor model: a room as ScanNet and phone or tablet apps deliver it.

A person walks around the room with a depth camera, the frames are fused into a mesh and the
mesh is sampled uniformly by area: every surface the camera saw has the same point density
(no falloff with distance, no scan lines), surfaces it never saw (under and behind furniture,
parts of the walls) are holes, and the ceiling is mostly missing. Here the walk and the casts
are the tablet's (:func:`generator.tablet.tablet_trajectory`, :func:`generator.tablet.cast_tablet`)
with a depth camera's settings, for ``oversample`` times the point budget; the fused surface is
one of those returns per cube of ``surface_spacing``, and the budget a uniform random subset of it.
"""
import math
import warnings
from typing import Any, Mapping, Sequence

import numpy as np

from generator.scanner import ScanResult, Scanner, row_norms
from generator.sensor_common import RoomGeometry, labelled_result
from generator.tablet import cast_tablet, tablet_trajectory
from synthdet.voxels import VoxelFilter

# the returns fused per call of the voxel filter: bounds the filter's hash table
FUSE_CHUNK = 4_000_000


def ceiling_triangles(scanner: Scanner, room: RoomGeometry, tolerance: float = 0.01) -> np.ndarray:
    """Per triangle of the scene: whether it belongs to the ceiling, a triangle of the room
    structure (not an object) whose three corners lie within ``tolerance`` of the room's
    height (the structure part ``ceiling_1``; a wall's triangles reach down to the floor)."""
    scene = scanner.scene
    corner_z = scene.vertices[scene.triangles, 2]  # (T, 3)
    structure = ~room.object_parts[scene.part]
    return structure & np.all(corner_z >= room.height - tolerance, axis=1)


def fused_surface(xyz: np.ndarray, spacing: float, offset: np.ndarray) -> np.ndarray:
    """Ascending indices of one point of ``xyz`` (N, 3) per occupied cube of ``spacing``
    metres, the cubes' grid shifted by ``offset`` (3,): the first of the cube's points
    (:class:`synthdet.voxels.VoxelFilter`)."""
    voxels = VoxelFilter(spacing, np.zeros(3))
    kept = [start + voxels.new_points(xyz[start:start + FUSE_CHUNK] - offset)
            for start in range(0, len(xyz), FUSE_CHUNK)]
    return np.concatenate(kept) if kept else np.zeros(0, dtype=np.int64)


def scan_reconstruction(
        scanner: Scanner,
        room: RoomGeometry,
        n_points: int,
        rng: np.random.Generator,
        cfg: Mapping[str, Any],
        batch: int,
        shiny_colors: Sequence[Sequence[int]] = ()) -> tuple[ScanResult, dict[str, Any]]:
    """Up to ``n_points`` points of the room's reconstruction, and the model's meta.json record
    (without the parameters: the walk's poses, the fused point count and the cubes' grid
    offset).

    1. The tablet's walk and casts with ``cfg`` (the ``scanner.reconstruction`` section) for
       ``oversample * n_points`` returns, without range error: the true surface. Each return's
       ray takes a uniform random pose and pixel, so the returns come in random order.
    2. The fused surface: the first return in every cube of ``surface_spacing`` metres (on a
       grid shifted by a uniform random offset), which by that random order is a uniform draw
       among the cube's returns. Wherever the walk put at least one return per cube, the density
       is one point per cube, near or far from the walk.
    3. Ceiling returns (:func:`ceiling_triangles`) are kept with probability ``ceiling_keep``.
    4. A uniform random subset of exactly ``n_points``; fewer, with a warning naming the
       shortfall, when the fused surface has fewer points.
    5. The fused surface's error: each point moves along its ray by a normal draw of std
       ``range_noise``.

    Every draw comes from ``rng``.
    """
    positions, look = tablet_trajectory(room, rng, cfg)
    wanted = int(math.ceil(cfg['oversample'] * n_points))
    with warnings.catch_warnings():
        # a shortfall of the oversampled casts is no shortfall of the budget: checked below
        warnings.simplefilter('ignore', UserWarning)
        # the true surface is fused; the fused surface's own error is added to the kept points
        raw, _ = cast_tablet(scanner, positions, look, wanted, rng, dict(cfg, range_noise=0.0),
                             batch, shiny_colors)
    # a grid shifted at random: a plane on a cube boundary (the floor at z = 0, a table top at
    # 0.75 m) would fill the cubes on both sides of it, twice the density
    offset = rng.uniform(0.0, cfg['surface_spacing'], 3)
    fused = fused_surface(raw.xyz, cfg['surface_spacing'], offset)
    on_ceiling = ceiling_triangles(scanner, room)[raw.triangle[fused]]
    kept = fused[~on_ceiling | (rng.random(len(fused)) < cfg['ceiling_keep'])]
    if len(kept) > n_points:
        kept = np.sort(rng.choice(kept, n_points, replace=False))
    elif len(kept) < n_points:
        warnings.warn(f'reconstruction: only {len(kept)} of {n_points} points on the fused '
                      f'surface ({len(fused)} cubes of {cfg["surface_spacing"]} m from '
                      f'{len(raw.xyz)} returns)')
    origin = raw.origin[kept]
    ray = raw.xyz[kept] - origin
    ray /= row_norms(ray) + 1e-12
    xyz = raw.xyz[kept] + ray * (rng.standard_normal(len(kept)) * cfg['range_noise'])[:, None]
    scan = labelled_result(scanner, xyz, raw.triangle[kept], origin, raw.rays_cast)
    return scan, {'trajectory': np.round(positions, 3).tolist(), 'fused_points': len(fused),
                  'grid_offset': offset.tolist()}
