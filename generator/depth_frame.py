"""The depth-frame sensor model: one frame of an RGB-D camera (Kinect-like, as a SUN RGB-D view).

One pose near a wall or in a corner, clear of objects, looking into the room and pitched down, a
pinhole pixel grid of the field of view, returns only between ``min_range`` and ``max_range``,
depth noise of std ``a + b * depth**2``, returns lost at depth edges and on dark and shiny
triangles; objects left with fewer than ``min_object_points`` returns lose them.
"""
import math
import warnings
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from generator.scanner import ScanResult, Scanner, row_norms
from generator.sensor_common import (RoomGeometry, cast_grid, depth_edges, labelled_result,
                                     obstacle_clearance, surface_loss)
from synthdet.geometry import distance_to_polygon, points_in_polygon


@dataclass
class DepthCamera:
    """One pose of a depth camera: position (3,), unit view direction (3,), unit right and up
    vectors of its image plane (3,), half tangents of its field of view (horizontal, vertical)
    and its range limit."""

    position: np.ndarray
    look: np.ndarray
    right: np.ndarray
    up: np.ndarray
    half_tan: np.ndarray
    max_range: float

    def record(self) -> dict[str, Any]:
        """The camera's entry of meta.json: pose, pitch, field of view and range limit."""
        return {
            'position': np.round(self.position, 6).tolist(),
            'look': np.round(self.look, 6).tolist(),
            'pitch_deg': round(math.degrees(math.asin(-self.look[2])), 4),
            'fov_deg': np.round(np.degrees(2 * np.arctan(self.half_tan)), 4).tolist(),
            'max_range': round(self.max_range, 6),
        }


def depth_frame_camera(room: RoomGeometry, rng: np.random.Generator,
                       cfg: Mapping[str, Any]) -> DepthCamera:
    """The pose of a depth frame: a person standing near a wall or in a corner with the camera.

    The position is drawn among random floor points of the room whose distance to the walls
    lies in ``wall_distance`` and that keep ``object_clearance`` from every object's bounds
    (else the clearest of them, else of any room point); the height is drawn from ``height``.
    The camera turns towards the centre of a random cell of the room or, with probability
    ``aim_at_objects``, towards a random object whose centre lies 1 m to ``max_range`` away and
    within 60 degrees of that way into the room (when there is one); it is pitched down by an
    angle drawn from ``pitch_deg``. The field of view (``horizontal_fov_deg``,
    ``vertical_fov_deg``) and ``max_range`` are drawn too.
    """
    low, high = room.polygon.min(axis=0), room.polygon.max(axis=0)
    xy = low + rng.random((512, 2)) * (high - low)
    xy = xy[points_in_polygon(xy, room.polygon)]
    wall = distance_to_polygon(xy, room.polygon)
    clearance = obstacle_clearance(xy, room.obstacles)
    near_wall = (wall >= cfg['wall_distance'][0]) & (wall <= cfg['wall_distance'][1])
    free = np.flatnonzero(near_wall & (clearance >= cfg['object_clearance']))
    if len(free):
        spot = xy[free[int(rng.integers(len(free)))]]
    else:
        pool = np.flatnonzero(near_wall) if near_wall.any() else np.arange(len(xy))
        spot = xy[pool[int(np.argmax(clearance[pool]))]]
    max_range = float(rng.uniform(*cfg['max_range']))
    cells = room.cells
    target = cells[int(rng.integers(len(cells)))].mean(axis=0)
    inward = (target - spot) / max(float(np.linalg.norm(target - spot)), 1e-9)
    offset = room.obstacles.mean(axis=1) - spot
    distance = np.linalg.norm(offset, axis=1)
    # objects in reach within 60 degrees of the way into the room (not along the wall)
    facing = offset @ inward >= 0.5 * distance
    reachable = np.flatnonzero((distance >= 1.0) & (distance <= max_range) & facing)
    if rng.random() < cfg['aim_at_objects'] and len(reachable):
        target = spot + offset[reachable[int(rng.integers(len(reachable)))]]
    yaw = math.atan2(target[1] - spot[1], target[0] - spot[0])
    pitch = -math.radians(rng.uniform(*cfg['pitch_deg']))
    look = np.array([math.cos(pitch) * math.cos(yaw), math.cos(pitch) * math.sin(yaw),
                     math.sin(pitch)])
    right = np.array([math.sin(yaw), -math.cos(yaw), 0.0])
    fov = np.radians([rng.uniform(*cfg['horizontal_fov_deg']),
                      rng.uniform(*cfg['vertical_fov_deg'])])
    position = np.array([spot[0], spot[1], rng.uniform(*cfg['height'])])
    return DepthCamera(position, look, right, np.cross(right, look), np.tan(fov / 2), max_range)


def depth_frame_rays(camera: DepthCamera, columns: int, rows: int) -> np.ndarray:
    """Unit directions (rows * columns, 3) through the pixel centres of a pinhole image of
    ``columns`` x ``rows`` pixels, row-major from the top left."""
    u = ((np.arange(columns) + 0.5) / columns * 2 - 1) * camera.half_tan[0]
    v = (1 - (np.arange(rows) + 0.5) / rows * 2) * camera.half_tan[1]
    plane = (camera.look[None, None, :] + u[None, :, None] * camera.right
             + v[:, None, None] * camera.up)
    plane = plane.reshape(-1, 3)
    return plane / row_norms(plane)


def depth_frame_returns(scanner: Scanner, camera: DepthCamera, columns: int, rows: int,
                        rng: np.random.Generator, cfg: Mapping[str, Any], batch: int,
                        on_object: np.ndarray,
                        loss: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The kept returns of one frame of ``columns`` x ``rows`` pixels: points (N, 3) and
    triangles (N,), in pixel order."""
    directions = depth_frame_rays(camera, columns, rows)
    origins = np.broadcast_to(camera.position, directions.shape)
    ranges, triangle = cast_grid(
        scanner, lambda start, stop: (origins[start:stop], directions[start:stop]),
        len(directions), batch, rng, cfg['min_range'], camera.max_range)
    # a lost column after each row: no depth edge across the image's left and right borders
    grid_ranges = np.full((rows, columns + 1), np.inf)
    grid_ranges[:, :columns] = ranges.reshape(rows, columns)
    grid_triangle = np.zeros((rows, columns + 1), triangle.dtype)
    grid_triangle[:, :columns] = triangle.reshape(rows, columns)
    edges, _, _ = depth_edges(grid_ranges.reshape(-1), grid_triangle.reshape(-1), columns + 1,
                              on_object, scanner.scene.part, cfg['edge_jump'])
    edges = edges[rng.random(len(edges)) < cfg['edge_dropout']]
    ranges[edges // (columns + 1) * columns + edges % (columns + 1)] = np.inf
    hit = np.flatnonzero(np.isfinite(ranges))
    hit = hit[rng.random(len(hit)) >= loss[triangle[hit]]]
    # structured-light / time-of-flight depth noise: its std grows with the square of the depth
    a, b = cfg['depth_noise']
    depth = ranges[hit] * (directions[hit] @ camera.look)
    measured = ranges[hit] + rng.standard_normal(len(hit)) * (a + b * depth**2)
    inside = (measured >= cfg['min_range']) & (measured <= camera.max_range)
    hit, measured = hit[inside], measured[inside]
    return camera.position + directions[hit] * measured[:, None], triangle[hit].astype(np.int64)


def cast_depth_frame(scanner: Scanner,
                     camera: DepthCamera,
                     n_points: int,
                     rng: np.random.Generator,
                     cfg: Mapping[str, Any],
                     batch: int,
                     object_parts: np.ndarray,
                     shiny_colors: Sequence[Sequence[int]] = ()) -> tuple[ScanResult, dict]:
    """Up to ``n_points`` returns of one depth frame, and the frame's meta.json record.

    The pixel grid has the field of view's aspect and about ``n_points / 0.7`` pixels; when the
    kept returns fall short of ``n_points`` the frame is cast again with the grid refined by the
    shortfall (up to 4 times, at most ``16 * n_points`` pixels). A return counts within
    [``min_range``, the camera's ``max_range``] (true and measured range); a pixel at a depth edge
    (:func:`generator.sensor_common._depth_edges`: a range step over ``edge_jump`` to a neighbour
    on another part, one of them an object) is lost with probability ``edge_dropout``, one on a
    dark or shiny triangle with ``dark_dropout`` / ``shiny_dropout``. Beyond ``n_points`` a uniform
    random subset is kept; fewer returns than requested are written with a warning. Then an object
    (``object_parts`` per part) with fewer than ``min_object_points`` returns loses them (the
    record counts them): a few returns of an object at the frame's border or behind another would
    become the annotated box of a sliver.
    """
    on_object = object_parts[scanner.scene.part]
    loss = surface_loss(scanner, cfg, shiny_colors)
    aspect = camera.half_tan[0] / camera.half_tan[1]
    pixels = n_points / 0.7
    rays = 0
    for _ in range(4):
        rows = max(2, int(round(math.sqrt(pixels / aspect))))
        columns = max(2, int(round(rows * aspect)))
        xyz, triangle = depth_frame_returns(scanner, camera, columns, rows, rng, cfg, batch,
                                            on_object, loss)
        rays += rows * columns
        if len(xyz) >= n_points or pixels >= 16 * n_points:
            break
        pixels = min(16 * n_points, pixels * 1.05 * n_points / max(len(xyz), n_points / 16))
    if len(xyz) > n_points:
        keep = np.sort(rng.choice(len(xyz), n_points, replace=False))
        xyz, triangle = xyz[keep], triangle[keep]
    elif len(xyz) < n_points:
        warnings.warn(f'depth frame: only {len(xyz)} of {n_points} points from a '
                      f'{columns} x {rows} pixel grid')
    part = scanner.scene.part[triangle]
    counts = np.bincount(part[on_object[triangle]], minlength=len(object_parts))
    sparse = np.flatnonzero(object_parts & (counts > 0) & (counts < cfg['min_object_points']))
    dropped = np.isin(part, sparse)
    xyz, triangle = xyz[~dropped], triangle[~dropped]
    record = dict(camera.record(), pixels=[columns, rows], sparse_objects=len(sparse),
                  sparse_object_points=int(dropped.sum()))
    origin = np.broadcast_to(camera.position, xyz.shape)
    return labelled_result(scanner, xyz, triangle, origin, rays), record
