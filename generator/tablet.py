"""The handheld tablet LiDAR sensor model.

A smooth walk around every cell at hand height that steps around objects, the device facing the
walls for most of the walk and the room's inside or the way ahead for the rest (swaying left and
right, tilting up and down), returns only between ``min_range`` and ``max_range``, range noise,
fewer returns far away and dropouts on dark triangles (luminance of the color below
``dark_luminance``) and shiny ones (colors of the metal palette). There is no object-ratio
phase: the share of object points is what the geometry gives.
"""
import warnings
from typing import Any, Mapping, Sequence

import numba
import numpy as np

from generator.counter_random import (DRAW_CHUNK, ITEM_COUNTERS, normals, stream_seed,
                                     uniform)
from generator.scanner import ScanResult, Scanner, row_norms
from generator.sensor_common import (RoomGeometry, inset_cell, labelled_result,
                                     obstacle_clearance, rows_of, surface_loss)
from synthdet.geometry import points_in_polygon


def _push_clear(xy: np.ndarray, centre: np.ndarray, obstacles: np.ndarray, clearance: float,
                polygon: np.ndarray) -> np.ndarray:
    """``xy`` (N, 2) moved out of every obstacle box grown by ``clearance``, straight to the
    side of the grown box nearest to the point's ``centre`` (N, 2) among those in ``polygon``:
    the walker passes an object on the room's side, not between it and a wall (a few passes,
    for boxes that touch); a point with no such side stays."""
    xy = xy.copy()
    for _ in range(4):
        moved = False
        for low, high in obstacles:
            low, high = low - clearance, high + clearance
            inside = np.flatnonzero(np.all((xy > low) & (xy < high), axis=1))
            if not len(inside):
                continue
            exits = np.repeat(xy[inside][:, None, :], 4, axis=1)  # (n, side, xy): -x +x -y +y
            exits[:, 0, 0], exits[:, 1, 0] = low[0], high[0]
            exits[:, 2, 1], exits[:, 3, 1] = low[1], high[1]
            distance = np.linalg.norm(exits - centre[inside][:, None, :], axis=2)
            in_room = points_in_polygon(exits.reshape(-1, 2), polygon).reshape(-1, 4)
            distance[~in_room] = np.inf
            side = np.argmin(distance, axis=1)
            free = np.isfinite(distance[np.arange(len(inside)), side])
            xy[inside[free]] = exits[np.flatnonzero(free), side[free]]
            moved |= bool(free.any())
        if not moved:
            break
    return xy


def tablet_trajectory(room: RoomGeometry, rng: np.random.Generator,
                      cfg: Mapping[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """Poses of a walk through the room: positions (P, 3) and view directions (P, 3).

    The walker goes once around every cell, ``wall_distance`` from its sides (starting corner and
    sense random), the loops joined in cell order; the polyline is resampled to ``poses`` points
    (per bay in a hall) and smoothed (rounded corners). Poses within 0.3 m of an object's bounds
    are pushed out to 0.3 m on the side towards the cell's centre (the walker steps around, on
    the room's side); poses then outside the room or still that near an object are dropped.
    The device is held at a height drawn from ``height``. Of every 2 m of walk, a share
    ``wall_look`` faces the nearest side of the cell (outwards, across the walk) and the rest
    the cell's centre or along the walk (drawn per 2 m). The view sways ``sway_deg`` left and
    right of that direction and tilts through ``pitch_deg``.
    """
    waypoints, centres = [], []
    for cell in room.cells:
        low, high = inset_cell(cell, cfg['wall_distance'])
        loop = np.array([[low[0], low[1]], [low[0], high[1]], [high[0], high[1]],
                         [high[0], low[1]]])
        loop = np.roll(loop, int(rng.integers(4)), axis=0)
        if rng.random() < 0.5:
            loop = loop[::-1]
        waypoints += [*loop, loop[0]]
        centres += [(low + high) / 2] * 5
    waypoints, centres = np.array(waypoints), np.array(centres)
    along = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(waypoints, axis=0), axis=1))])
    s = np.linspace(0.0, along[-1], int(cfg['poses']) * max(1, len(room.bays)))
    xy = np.stack([np.interp(s, along, waypoints[:, i]) for i in range(2)], axis=1)
    # the cell each pose walks around: the one of the loop's waypoints
    centre = centres[np.minimum(np.searchsorted(along, s, side='right') - 1, len(centres) - 1)]
    window = max(1, int(round(0.6 / max(s[1] - s[0], 1e-6)))) if len(s) > 1 else 1
    kernel = np.ones(2 * window + 1) / (2 * window + 1)
    padded = np.pad(xy, ((window, window), (0, 0)), mode='edge')
    xy = np.stack([np.convolve(padded[:, i], kernel, mode='valid') for i in range(2)], axis=1)
    step = np.gradient(xy, axis=0)
    heading = np.arctan2(step[:, 1], step[:, 0])
    # across the walk, towards the side of the cell the walker is nearest to
    outward = heading + np.pi / 2
    away = xy - centre
    flip = np.cos(outward) * away[:, 0] + np.sin(outward) * away[:, 1] < 0
    outward[flip] -= np.pi
    inward = np.arctan2(-away[:, 1], -away[:, 0])
    # every 2 m of walk: a share wall_look facing the wall, the rest inwards or ahead
    offset = rng.uniform(0.0, 2.0)
    stretch = np.floor((s + offset) / 2.0).astype(int)
    to_wall = ((s + offset) / 2.0) % 1.0 < cfg['wall_look']
    to_centre = rng.random(int(stretch.max()) + 1) < 0.5
    base = np.where(to_wall, outward, np.where(to_centre[stretch], inward, heading))
    phase = rng.uniform(0, 2 * np.pi, 2)
    yaw = base + np.radians(cfg['sway_deg']) * np.sin(2 * np.pi * s / 4.0 + phase[0])
    low_pitch, high_pitch = np.radians(cfg['pitch_deg'])
    pitch = low_pitch + (high_pitch - low_pitch) * (0.5 +
                                                    0.5 * np.sin(2 * np.pi * s / 2.5 + phase[1]))
    look = np.stack([np.cos(pitch) * np.cos(yaw), np.cos(pitch) * np.sin(yaw), np.sin(pitch)], 1)
    xy = _push_clear(xy, centre, room.obstacles, 0.3, room.polygon)
    positions = np.column_stack([xy, np.full(len(xy), rng.uniform(*cfg['height']))])
    clear = obstacle_clearance(xy, room.obstacles) > 0.3 - 1e-6
    keep = points_in_polygon(xy, room.polygon) & clear
    if not keep.any():
        raise ValueError('tablet: every pose of the walk is inside an object or outside the room')
    return positions[keep], look[keep]


@numba.njit(cache=True, nogil=True, inline='always')
def _tablet_ray(positions: np.ndarray, look: np.ndarray, right: np.ndarray, up: np.ndarray,
                seed: np.uint64, half: np.ndarray, ray: int) -> tuple[int, float, float, float]:
    """Ray ``ray`` of a batch: a uniform random pose and a uniform random pixel
    ``(u * 2 - 1) * half`` (right, up offsets on the image plane at distance 1), drawn from the
    stream ``seed``: the pose and the direction (not of unit length)."""
    # the ray's counters: its pose, its pixel (two), whether its return is kept, then its range
    # error
    counter = np.uint64(ray) * ITEM_COUNTERS
    p = min(int(uniform(seed, counter) * len(positions)), len(positions) - 1)
    across = (uniform(seed, counter + np.uint64(1)) * 2 - 1) * half[0]
    above = (uniform(seed, counter + np.uint64(2)) * 2 - 1) * half[1]
    x = look[p, 0] + across * right[p, 0] + above * up[p, 0]
    y = look[p, 1] + across * right[p, 1] + above * up[p, 1]
    z = look[p, 2] + across * right[p, 2] + above * up[p, 2]
    return p, x, y, z


@numba.njit(cache=True, nogil=True)
def tablet_rays(positions: np.ndarray, look: np.ndarray, right: np.ndarray, up: np.ndarray,
                seed: np.uint64, half: np.ndarray, cast_origins: np.ndarray,
                cast_directions: np.ndarray) -> None:
    """Write the rays of a batch (:func:`_tablet_ray`) as the float32 origins and unit
    directions (N, 3) Embree casts; :func:`tablet_points` draws the kept ones again in float64
    (the batch's rays are written once, in half the memory)."""
    for ray in range(len(cast_origins)):
        p, x, y, z = _tablet_ray(positions, look, right, up, seed, half, ray)
        norm = np.sqrt((x * x + y * y) + z * z)
        cast_directions[ray, 0] = x / norm
        cast_directions[ray, 1] = y / norm
        cast_directions[ray, 2] = z / norm
        for axis in range(3):
            cast_origins[ray, axis] = positions[p, axis]


@numba.njit(cache=True, nogil=True)
def tablet_returns(t_hit: np.ndarray, primitive: np.ndarray, seed: np.uint64,
                   loss: np.ndarray, range_noise: float, far_keep: float, near: float,
                   far: float, most: int) -> tuple[np.ndarray, np.ndarray]:
    """The first ``most`` of the batch's hits the tablet keeps and their measured ranges: the
    distance plus a standard normal draw x ``range_noise`` within [near, far], kept when a
    uniform draw is below the keep probability (falling from 1 at ``near`` to ``far_keep`` at
    ``far``, times one minus the triangle's ``loss``); the draws from the stream ``seed``."""
    wanted = min(len(t_hit), max(most, 0))
    # one place more: each hit is written to the next place, which it keeps when kept (no
    # branch on a draw)
    kept = np.empty(wanted + 1, dtype=np.int64)
    measured = np.empty(wanted + 1)
    errors = np.empty(DRAW_CHUNK)
    count = 0
    for first in range(0, len(t_hit), DRAW_CHUNK):
        if count == wanted:  # no draws for the rays after the last return wanted
            break
        stop = min(first + DRAW_CHUNK, len(t_hit))
        normals(seed, first, stop, 4, errors)  # the range errors
        for ray in range(first, stop):
            if count == wanted:
                break
            if not np.isfinite(t_hit[ray]):
                continue
            counter = np.uint64(ray) * ITEM_COUNTERS
            distance = np.float64(t_hit[ray]) + errors[ray - first] * range_noise
            keep = 1.0 - (1.0 - far_keep) * (distance - near) / (far - near)
            keep *= 1.0 - loss[primitive[ray]]
            kept[count], measured[count] = ray, distance
            count += (distance >= near) & (distance <= far) & (uniform(
                seed, counter + np.uint64(3)) < keep)
    return kept[:count], measured[:count]


@numba.njit(cache=True, nogil=True)
def tablet_points(positions: np.ndarray, look: np.ndarray, right: np.ndarray, up: np.ndarray,
                  seed: np.uint64, half: np.ndarray, primitive: np.ndarray, rows: np.ndarray,
                  measured: np.ndarray, xyz: np.ndarray, triangle: np.ndarray,
                  pose_of: np.ndarray) -> None:
    """Write the returns of ``rows`` of the batch of stream ``seed`` (:func:`_tablet_ray`):
    points at origin + unit direction x measured range into ``xyz`` (N, 3), their triangles and
    poses into ``triangle`` and ``pose_of`` (N,)."""
    for k in range(len(rows)):
        ray = rows[k]
        p, x, y, z = _tablet_ray(positions, look, right, up, seed, half, ray)
        norm = np.sqrt((x * x + y * y) + z * z)
        xyz[k, 0] = positions[p, 0] + x / norm * measured[k]
        xyz[k, 1] = positions[p, 1] + y / norm * measured[k]
        xyz[k, 2] = positions[p, 2] + z / norm * measured[k]
        triangle[k], pose_of[k] = primitive[ray], p


def cast_tablet(
    scanner: Scanner,
    positions: np.ndarray,
    look: np.ndarray,
    n_points: int,
    rng: np.random.Generator,
    cfg: Mapping[str, Any],
    batch: int,
    shiny_colors: Sequence[Sequence[int]] = ()) -> tuple[ScanResult, np.ndarray]:
    """Up to ``n_points`` tablet returns and the pose index (N,) of each.

    Each ray takes a random pose and a uniform random pixel of the image plane (``fov_deg``
    horizontal x vertical). A return counts when its measured range (true range plus noise of
    std ``range_noise``) lies in [``min_range``, ``max_range``]; it is kept with a probability
    falling linearly from 1 at ``min_range`` to ``far_keep`` at ``max_range``, and lost with
    ``dark_dropout`` on dark and ``shiny_dropout`` on shiny triangles.
    """
    loss = surface_loss(scanner, cfg, shiny_colors)
    right = np.stack([look[:, 1], -look[:, 0], np.zeros(len(look))], axis=1)
    right /= row_norms(right) + 1e-12
    up = np.cross(right, look)
    half = np.tan(np.radians(np.asarray(cfg['fov_deg'], dtype=np.float64)) / 2)
    near, far = cfg['min_range'], cfg['max_range']
    # the returns, written in place batch by batch
    xyz = np.empty((n_points, 3))
    triangle = np.empty(n_points, dtype=np.int64)
    pose_of = np.empty(n_points, dtype=np.int64)
    # one batch's rays, reused by every batch
    cast_origins = np.empty((batch, 3), dtype=np.float32)
    cast_directions = np.empty((batch, 3), dtype=np.float32)
    got = rays = 0
    max_batches = max(64, 16 * n_points // batch + 64)
    for _ in range(max_batches):
        if got >= n_points:
            break
        seed = stream_seed(rng)  # the batch's poses, pixels, range errors and dropouts
        tablet_rays(positions, look, right, up, seed, half, cast_origins, cast_directions)
        t_hit, prim = scanner.cast(scanner.full_scene, cast_origins, cast_directions, rng)
        rays += batch
        rows, measured = tablet_returns(t_hit, prim, seed, loss, cfg['range_noise'],
                                        cfg['far_keep'], near, far, n_points - got)
        end = got + len(rows)
        tablet_points(positions, look, right, up, seed, half, prim, rows, measured,
                      xyz[got:end], triangle[got:end], pose_of[got:end])
        got = end
    if got < n_points:
        warnings.warn(f'tablet: only {got} of {n_points} points after {rays} rays')
    pose = pose_of[:got]
    origin = rows_of(positions.astype(np.float32), pose)
    return labelled_result(scanner, xyz[:got], triangle[:got], origin, rays), pose
