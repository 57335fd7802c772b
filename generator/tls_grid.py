"""The laser scanner's beam grid: its angles, the beams' directions and the points of returns.

A station's grid is elevation-major: beam ``k`` is row ``k // A`` (an elevation) and column
``k % A`` (an azimuth) of ``A`` azimuths.
"""
import math

import numba
import numpy as np


def tls_grid(step_deg: float, min_elevation_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Azimuths and elevations (radians) of the beam grid: multiples of the step, elevations from
    ``min_elevation_deg`` up to below the zenith."""
    n_azimuth = int(round(360.0 / step_deg))
    azimuth = np.arange(n_azimuth) * step_deg
    first, last = math.ceil(min_elevation_deg / step_deg - 1e-9), math.ceil(90.0 / step_deg) - 1
    elevation = np.arange(first, last + 1) * step_deg
    return np.radians(azimuth), np.radians(elevation)


def angle_tables(azimuth: np.ndarray,
                 elevation: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Cosines and sines of the grid's elevations and azimuths (numpy's, computed once)."""
    return np.cos(elevation), np.sin(elevation), np.cos(azimuth), np.sin(azimuth)


@numba.njit(cache=True, nogil=True)
def grid_directions(cos_elevation: np.ndarray, sin_elevation: np.ndarray,
                    cos_azimuth: np.ndarray, sin_azimuth: np.ndarray, start: int,
                    directions: np.ndarray) -> None:
    """Write the unit directions of the grid's beams ``start`` on (elevation-major) into
    ``directions`` (N, 3), as the float32 rays Embree casts.

    Each component is the float64 product of an elevation's and an azimuth's cosine or sine
    (:func:`grid_points` recomputes the same products for the returns), rounded to float32."""
    columns = len(cos_azimuth)
    row, column = start // columns, start % columns  # then counted on, without divisions
    for k in range(len(directions)):
        directions[k, 0] = cos_elevation[row] * cos_azimuth[column]
        directions[k, 1] = cos_elevation[row] * sin_azimuth[column]
        directions[k, 2] = sin_elevation[row]
        row, column = next_beam(row, column, columns)


@numba.njit(cache=True, nogil=True)
def next_beam(row: int, column: int, columns: int) -> tuple[int, int]:
    """The row and column of the beam after the one at (``row``, ``column``) in a grid of
    ``columns`` azimuths (elevation-major: counted on without divisions)."""
    column += 1
    if column == columns:
        return row + 1, 0
    return row, column


@numba.njit(cache=True, nogil=True)
def grid_points(station: np.ndarray, cos_elevation: np.ndarray, sin_elevation: np.ndarray,
                cos_azimuth: np.ndarray, sin_azimuth: np.ndarray, beams: np.ndarray,
                measured: np.ndarray) -> np.ndarray:
    """Points (N, 3) of ``beams`` (grid indices) at their ``measured`` ranges (N,)."""
    columns = len(cos_azimuth)
    xyz = np.empty((len(beams), 3))
    row, first = 0, 0  # the row of the last beam and its first beam
    for k in range(len(beams)):
        beam = beams[k]
        # the row from a division only when it changes (ascending beams mostly stay in it)
        if beam < first or beam >= first + columns:
            row = beam // columns
            first = row * columns
        column = beam - first
        xyz[k, 0] = station[0] + cos_elevation[row] * cos_azimuth[column] * measured[k]
        xyz[k, 1] = station[1] + cos_elevation[row] * sin_azimuth[column] * measured[k]
        xyz[k, 2] = station[2] + sin_elevation[row] * measured[k]
    return xyz
