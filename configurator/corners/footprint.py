"""The traced boundary of a scan's footprint in the wall-aligned frame."""
from __future__ import annotations
import math

import numpy as np
from scipy import ndimage

from configurator.corners.params import CornerParams
from configurator.lattice_outline import trace_boundary


def traced_outline(frame_xy: np.ndarray, params: CornerParams) -> tuple[np.ndarray, float, float]:
    """Trace the boundary of the points' footprint.

    Returns the clockwise polygon, the grid cell and the largest boundary error to expect
    (metres). The footprint is found at two scales: the fine grid gives accurate edges
    where the scan is dense, a grid ``coarse_factor`` times coarser adds the regions the
    fine grid sees as empty because they were scanned sparsely (such as the far arm of a
    U-shaped room); a thin rim of the coarse footprint around the fine one is dropped.
    """
    low = frame_xy.min(axis=0)
    extent = frame_xy.max(axis=0) - low
    area = max(float(extent[0] * extent[1]), 1e-6)
    cell = float(
        np.clip(
            math.sqrt(params.points_per_cell * area / len(frame_xy)), params.min_cell,
            params.max_cell))
    factor = max(2, math.ceil(params.coarse_cell / cell))
    pad = 2 * factor
    shape = np.floor(extent / cell).astype(int) + 1 + 2 * pad
    shape = -(-shape // factor) * factor  # whole coarse cells
    keys = np.floor((frame_xy - low) / cell).astype(np.int64) + pad
    counts = np.bincount(
        keys[:, 0] * shape[1] + keys[:, 1], minlength=shape[0] * shape[1]).reshape(shape)
    fine = _solid_footprint(counts > 0, params.min_island_cells, iterations=2)
    coarse_counts = counts.reshape(shape[0] // factor, factor, shape[1] // factor,
                                   factor).sum(axis=(1, 3))
    coarse = _solid_footprint(coarse_counts >= 2, params.min_island_cells, iterations=1)
    coarse = np.repeat(np.repeat(coarse, factor, axis=0), factor, axis=1)
    square = np.ones((3, 3), dtype=bool)
    sparse = ndimage.binary_opening(coarse & ~fine, square, iterations=factor)
    labels, _ = ndimage.label(sparse)
    sizes = np.bincount(labels.ravel()) * cell**2
    sparse &= sizes[labels] >= params.min_sparse_area  # whole room parts, not outlier bumps
    footprint = ndimage.binary_fill_holes(ndimage.binary_closing(fine | sparse, square))
    labels, count = ndimage.label(footprint)
    if count == 0:
        return np.zeros((0, 2)), cell, cell
    sizes = np.bincount(labels.ravel())
    sizes[0] = 0
    footprint = labels == int(np.argmax(sizes))
    loop = trace_boundary(footprint)
    origin = low - pad * cell
    error = factor * cell if (sparse & footprint).any() else 2 * cell
    return origin + loop * cell, cell, error


def _solid_footprint(occupied: np.ndarray, min_island: int, iterations: int) -> np.ndarray:
    """Occupied cells without small islands, closed, hole-filled and opened."""
    square = np.ones((3, 3), dtype=bool)
    # small islands (outliers) go before closing could join them into loops around empty cells
    labels, _ = ndimage.label(occupied, square)
    sizes = np.bincount(labels.ravel())
    occupied = occupied & (sizes[labels] >= min_island)
    occupied = ndimage.binary_closing(occupied, square, iterations=iterations)
    occupied = ndimage.binary_fill_holes(occupied)
    return ndimage.binary_opening(occupied, square, iterations=iterations)
