"""E57 scans by ``pye57`` (imported when a file is read or written): every scan of the file,
cartesian or spherical, each moved by its pose into the file's frame."""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Iterator, Sequence

import numpy as np

from synthdet.scan_io.common import (Scale, ScanFormatError, colors_0_255, grey, no_color_note,
                                     one_line)


def read_chunks(path: Path, chunk_points: int, columns: tuple[str, ...] | None,
                notes: list[str]) -> Iterator[np.ndarray]:
    """``(n, 6)`` chunks of every scan of the file, each moved by its pose."""
    import pye57
    try:
        e57 = pye57.E57(os.fspath(path))
    except Exception as error:  # libE57 raises its own exception type
        raise ScanFormatError(f'{path}: not a readable E57 file ({one_line(error)})') from None
    try:
        scan_count = e57.scan_count
        missing = 0
        for index in range(scan_count):
            fields = set(e57.get_header(index).point_fields)
            has_color = {'colorRed', 'colorGreen', 'colorBlue'} <= fields
            missing += not has_color
            yield from _e57_scan_chunks(path, e57, index, fields, has_color, chunk_points)
        if missing:
            note = no_color_note(path, True)
            notes.append(note if missing ==
                         scan_count else f'{note} ({missing} of {scan_count} scans)')
    finally:
        e57.close()


def _e57_scan_chunks(path: Path, e57, index: int, fields: set[str], has_color: bool,
                     chunk_points: int) -> Iterator[np.ndarray]:
    """The points of the E57 file's scan ``index``, moved by its pose into the file's frame."""
    header = e57.get_header(index)
    cartesian = ['cartesianX', 'cartesianY', 'cartesianZ']
    spherical = ['sphericalRange', 'sphericalAzimuth', 'sphericalElevation']
    coordinates = cartesian if set(cartesian) <= fields else spherical
    if not set(coordinates) <= fields:
        raise ScanFormatError(f'{path}: scan {index} has neither cartesian '
                              f'nor spherical coordinates')
    invalid = 'cartesianInvalidState' if coordinates is cartesian else 'sphericalInvalidState'
    color_names = ['colorRed', 'colorGreen', 'colorBlue']
    wanted = coordinates + (
        color_names if has_color else ['intensity'] if 'intensity' in fields else [])
    wanted += [invalid] if invalid in fields else []
    capacity = max(1, min(chunk_points, header.point_count))
    buffers_by_name, buffers = e57.make_buffers(wanted, capacity)
    rotation, translation = np.eye(3), np.zeros(3)
    if header.has_pose():
        rotation = _quaternion_matrix(np.asarray(header.rotation, dtype=np.float64))
        translation = np.asarray(header.translation, dtype=np.float64)
    scale = Scale(*_e57_limits(header, 'colorRed' if has_color else 'intensity'))
    reader = header.points.reader(buffers)
    try:
        while True:
            count = reader.read()
            if count == 0:
                break
            values = {name: buffers_by_name[name][:count] for name in wanted}
            xyz = np.column_stack([values[name].astype(np.float64) for name in coordinates])
            if coordinates is spherical:
                xyz = _spherical_to_cartesian(xyz)
            chunk = np.zeros((count, 6))
            chunk[:, :3] = xyz @ rotation.T + translation
            if has_color:
                chunk[:, 3:] = scale(np.column_stack([values[name] for name in color_names]))
            elif 'intensity' in values:
                chunk[:, 3:] = grey(scale(values['intensity']))
            if invalid in values:
                chunk = chunk[values[invalid] == 0]
            yield chunk
    finally:
        reader.close()


def _e57_limits(header, name: str) -> tuple[float | None, float | None]:
    """The header's color or intensity limits (``colorRedMinimum``...), if it has them."""
    node = {'colorRed': 'colorLimits', 'intensity': 'intensityLimits'}[name]
    try:
        limits = header[node]
        return float(limits[f'{name}Minimum'].value()), float(limits[f'{name}Maximum'].value())
    except Exception:  # libE57 raises its own exception type for absent nodes
        return None, None


def _quaternion_matrix(quaternion: np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion ``(w, x, y, z)``."""
    w, x, y, z = quaternion / np.linalg.norm(quaternion)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _matrix_quaternion(rotation: np.ndarray) -> np.ndarray:
    """Unit quaternion ``(w, x, y, z)`` of a rotation matrix (w >= 0)."""
    w = math.sqrt(max(0.0, 1.0 + np.trace(rotation))) / 2
    if w > 1e-6:
        x = (rotation[2, 1] - rotation[1, 2]) / (4 * w)
        y = (rotation[0, 2] - rotation[2, 0]) / (4 * w)
        z = (rotation[1, 0] - rotation[0, 1]) / (4 * w)
        return np.array([w, x, y, z])
    axis_values, axis_vectors = np.linalg.eigh(rotation + rotation.T)  # 180 degree turn
    x, y, z = axis_vectors[:, int(np.argmax(axis_values))]
    return np.array([0.0, x, y, z])


def _spherical_to_cartesian(rae: np.ndarray) -> np.ndarray:
    """E57 spherical ``range, azimuth, elevation`` (metres, radians) to ``x y z``."""
    horizontal = rae[:, 0] * np.cos(rae[:, 2])
    return np.column_stack([
        horizontal * np.cos(rae[:, 1]), horizontal * np.sin(rae[:, 1]),
        rae[:, 0] * np.sin(rae[:, 2])
    ])


def write(path: Path, points: np.ndarray) -> None:
    """One E57 file of one scan (see :func:`write_e57_scans`)."""
    write_e57_scans(path, [(points, np.eye(3), np.zeros(3))])


def write_e57_scans(path: str | os.PathLike, scans: Sequence[tuple[np.ndarray, np.ndarray,
                                                                   np.ndarray]]) -> None:
    """Write ``(points, rotation, translation)`` scans into one E57 file.

    Each scan's ``(n, 6)`` points are in its own frame; its pose (3x3 rotation, translation)
    moves them into the file's. The points are stored as float32 around their floored
    minimum, which is folded into the float64 pose translation, so georeferenced coordinates
    keep sub-millimetre precision.
    """
    import pye57
    e57 = pye57.E57(os.fspath(path), mode='w')
    try:
        for points, rotation, translation in scans:
            points = np.asarray(points, dtype=np.float64)
            rotation = np.asarray(rotation, dtype=np.float64)
            shift = np.floor(points[:, :3].min(axis=0))
            local = points[:, :3] - shift
            colors = colors_0_255(points).astype(np.uint8)
            data = {
                'cartesianX': local[:, 0],
                'cartesianY': local[:, 1],
                'cartesianZ': local[:, 2],
                'colorRed': colors[:, 0],
                'colorGreen': colors[:, 1],
                'colorBlue': colors[:, 2],
            }
            e57.write_scan_raw(
                data,
                rotation=_matrix_quaternion(rotation),
                translation=rotation @ shift + np.asarray(translation, float))
    finally:
        e57.close()
