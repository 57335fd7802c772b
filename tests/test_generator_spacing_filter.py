"""The laser scanner's spacing filter and chunked draws keep the results of the plain numpy
versions they replace: the same returns, the same numbers, the same generator state."""
import numpy as np

from generator.tls import (SpacingFilter, _add_range_noise, _angle_tables, _grid_points,
                           _uniform_at, tls_grid)
from synthdet.voxels import VoxelFilter


def _station_grid(rng: np.random.Generator, step: float):
    azimuth, elevation = tls_grid(step, -60.0)
    angles = _angle_tables(azimuth, elevation)
    ranges = rng.uniform(0.6, 8.0, len(azimuth) * len(elevation))
    ranges[rng.random(len(ranges)) < 0.1] = np.inf
    return angles, ranges


def test_spacing_filter_keeps_the_voxel_filters_returns():
    rng = np.random.default_rng(3)
    stations = np.array([[1.0, 2.0, 1.5], [4.0, -1.0, 1.6], [2.5, 0.5, 1.4]])
    side = 0.05
    fused, reference = SpacingFilter(side, stations[0]), VoxelFilter(side, stations[0])
    total = 0
    for station in stations:
        angles, ranges = _station_grid(rng, 1.0)
        # a few returns 2**20 cubes and more away: kept by their exact cube
        ranges[rng.choice(len(ranges), 5, replace=False)] = 2**20 * side * 1.5
        beams = np.flatnonzero(np.isfinite(ranges))
        order = rng.permutation(len(beams))
        kept = fused.new_returns(station, angles, ranges, beams, order)
        first = reference.new_points(_grid_points(station, *angles, ranges, beams, True, order))
        expected = np.zeros(len(beams), dtype=bool)
        expected[order[first]] = True
        np.testing.assert_array_equal(kept, np.flatnonzero(expected))
        total += len(kept)
    assert 0 < total < 3 * len(beams)  # the filter dropped returns, and kept some
    assert fused.count == len(reference.seen) and fused.wide == reference.wide
    assert fused.wide  # the far returns were met


def test_chunked_draws_give_the_same_numbers_and_state():
    size = 200_003  # several chunks and a partial one
    index = np.sort(np.random.default_rng(0).choice(size, 999, replace=False))
    chunked, whole = np.random.default_rng(7), np.random.default_rng(7)
    np.testing.assert_array_equal(_uniform_at(chunked, size, index), whole.random(size)[index])
    assert chunked.random() == whole.random()

    ranges = np.random.default_rng(1).uniform(0.5, 9.0, size)
    rows = np.flatnonzero(np.random.default_rng(2).random(size) < 0.9)
    a, b = 0.002, 0.0005
    expected = ranges.copy()
    expected[rows] += whole.standard_normal(len(rows)) * (a + b * ranges[rows])
    _add_range_noise(chunked, ranges, rows, a, b)
    np.testing.assert_array_equal(ranges, expected)
    assert chunked.random() == whole.random()
