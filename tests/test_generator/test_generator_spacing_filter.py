"""The laser scanner's export (spacing filter, range noise, the final subset) and the
counter-based draws the sensor models make in their kernels: the distributions they promise
(normal and uniform draws, one return per cube drawn uniformly among the cube's returns, every
cube represented, noise of the configured std, a subset of exactly the wanted size, every subset
equally likely), the same numbers from the same seed, and the kernels' branch-free passes and
cast slices giving what the rules they implement give."""
import numba
import numpy as np
import pytest
from scipy import stats

from generator.config import DEFAULTS
from generator.counter_random import normal, uniform
from generator.scanner import Scanner, aimed_rays, path_rays
from generator.sensor_common import depth_edges
from generator.spacing_filter import SpacingFilter, beam_priorities
from generator.tablet import tablet_points, tablet_returns, tablet_rays
from generator.tls import add_range_noise, cast_tls, mix_at_depth_edges, uniform_subset
from generator.tls_grid import angle_tables, grid_points, tls_grid


@numba.njit
def _normals(seed: np.uint64, count: int) -> np.ndarray:
    return np.array([normal(seed, np.uint64(256 * k)) for k in range(count)])


@numba.njit
def _uniforms(seed: np.uint64, count: int) -> np.ndarray:
    return np.array([uniform(seed, np.uint64(k)) for k in range(count)])


def test_counter_draws_are_standard_normal_and_uniform_and_repeat_with_their_seed():
    draws = _normals(np.uint64(11), 400_000)
    assert abs(draws.mean()) < 0.01 and abs(draws.std() - 1.0) < 0.01
    assert stats.kstest(draws, 'norm').pvalue > 1e-3
    # the ziggurat's tail (beyond 3.4426) and its wedges give the normal's share there
    tail = 2 * stats.norm.sf(3.442619855899)
    assert abs(np.mean(np.abs(draws) > 3.442619855899) / tail - 1.0) < 0.15
    assert np.abs(draws).max() > 3.9
    flat = _uniforms(np.uint64(5), 400_000)
    assert flat.min() >= 0.0 and flat.max() < 1.0
    assert stats.kstest(flat, 'uniform').pvalue > 1e-3
    np.testing.assert_array_equal(_normals(np.uint64(11), 1000), draws[:1000])
    assert not np.array_equal(_normals(np.uint64(12), 1000), draws[:1000])


def _station_grid(rng: np.random.Generator, step: float):
    azimuth, elevation = tls_grid(step, -60.0)
    angles = angle_tables(azimuth, elevation)
    ranges = rng.uniform(0.6, 8.0, len(azimuth) * len(elevation))
    ranges[rng.random(len(ranges)) < 0.1] = np.inf
    return angles, ranges


def _cubes(points: np.ndarray, side: float, origin: np.ndarray) -> list[tuple]:
    return [tuple(c) for c in (np.floor(points / side) - np.floor(origin / side)).astype(int)]


def test_spacing_filter_keeps_the_smallest_priority_return_of_every_new_cube():
    rng = np.random.default_rng(3)
    stations = np.array([[1.0, 2.0, 1.5], [4.0, -1.0, 1.6], [2.5, 0.5, 1.4]])
    side = 0.05
    spacing = SpacingFilter(side, stations[0])
    seen: set[tuple] = set()
    for number, station in enumerate(stations):
        angles, ranges = _station_grid(rng, 1.0)
        # a few returns 2**20 cubes and more away: kept by their exact cube
        ranges[rng.choice(len(ranges), 5, replace=False)] = 2**20 * side * 1.5
        seed = np.uint64(100 + number)
        kept = spacing.new_returns(station, angles, ranges, seed)
        beams = np.flatnonzero(np.isfinite(ranges))
        cubes = _cubes(grid_points(station, *angles, beams, ranges[beams]), side, stations[0])
        priority = beam_priorities(seed, beams)
        # the reference: per cube not seen before, the return of smallest priority
        best: dict[tuple, int] = {}
        for index, cube in enumerate(cubes):
            if cube not in seen and (cube not in best or priority[index] < priority[best[cube]]):
                best[cube] = index
        np.testing.assert_array_equal(kept, np.sort(beams[list(best.values())]))
        kept_cubes = _cubes(grid_points(station, *angles, kept, ranges[kept]), side,
                            stations[0])
        # one return per cube, and every cube of the returns represented (here or before)
        assert len(set(kept_cubes)) == len(kept_cubes)
        assert set(kept_cubes) == set(cubes) - seen
        seen |= set(kept_cubes)
        assert 0 < len(kept) < len(beams)
    assert spacing.count + len(spacing.wide) == len(seen) and spacing.wide


def test_a_filter_on_the_released_memory_of_the_last_keeps_the_same_returns():
    rng = np.random.default_rng(8)
    station = np.array([1.0, 2.0, 1.5])
    angles, ranges = _station_grid(rng, 1.0)
    first = SpacingFilter(0.02, station)
    kept = first.new_returns(station, angles, ranges, np.uint64(1))
    table = first.table
    assert (table[1::2] == -1).all()  # the station is done: no choice held
    first.release()
    again = SpacingFilter(0.02, station)
    assert again.table is table  # the same memory, emptied
    np.testing.assert_array_equal(again.new_returns(station, angles, ranges, np.uint64(1)), kept)
    assert again.count == first.count


def test_spacing_filter_draws_each_return_of_a_cube_equally_often():
    # one station, five returns in one cube (along one grid row, in a cube of 10 m): the kept
    # return is uniform over the five across seeds
    azimuth, elevation = tls_grid(5.0, -60.0)
    angles = angle_tables(azimuth, elevation)
    ranges = np.full(len(azimuth) * len(elevation), np.inf)
    row = len(elevation) // 2
    beams = row * len(azimuth) + np.arange(5)
    ranges[beams] = 1.0 + 0.001 * np.arange(5)
    station = np.array([5.0, 5.0, 5.0])
    wins = np.zeros(5, dtype=int)
    for seed in range(1000):
        kept = SpacingFilter(10.0, station).new_returns(station, angles, ranges,
                                                      np.uint64(seed))
        assert len(kept) == 1
        wins[kept[0] - beams[0]] += 1
    assert stats.chisquare(wins).pvalue > 1e-3


def test_range_noise_has_the_configured_std_and_spares_lost_beams():
    ranges = np.random.default_rng(1).uniform(0.5, 20.0, 400_000)
    ranges[::7] = np.inf
    a, b = 0.002, 0.0005
    noisy = ranges.copy()
    add_range_noise(noisy, np.uint64(9), a, b)
    finite = np.isfinite(ranges)
    assert not np.isfinite(noisy[~finite]).any()
    error = (noisy[finite] - ranges[finite]) / (a + b * ranges[finite])
    assert abs(error.mean()) < 0.01 and abs(error.std() - 1.0) < 0.01
    again = ranges.copy()
    add_range_noise(again, np.uint64(9), a, b)
    np.testing.assert_array_equal(again, noisy)


def test_the_final_subset_has_exactly_the_wanted_size_and_every_item_the_same_chance():
    total, wanted = 50, 20
    taken = np.zeros(total, dtype=int)
    for seed in range(4000):
        chosen = uniform_subset(total, wanted, np.uint64(seed))
        assert len(chosen) == wanted and np.all(np.diff(chosen) > 0)
        assert chosen[0] >= 0 and chosen[-1] < total
        taken[chosen] += 1
    # each item in wanted / total of the subsets
    assert stats.chisquare(taken).pvalue > 1e-3
    # the pairs too (a subset, not independent picks): items 0 and 1 together
    both = sum(set(uniform_subset(total, wanted, np.uint64(s))) >= {0, 1} for s in range(4000))
    expected = 4000 * wanted * (wanted - 1) / (total * (total - 1))
    assert abs(both - expected) < 4 * np.sqrt(expected)
    np.testing.assert_array_equal(uniform_subset(10, 10, np.uint64(1)), np.arange(10))


def test_aimed_rays_pick_targets_by_their_weights():
    path = np.zeros((4, 3))
    low = np.array([[2.0, -0.5, -0.5], [-0.5, 2.0, -0.5], [-0.5, -0.5, 2.0]])
    extent = np.ones((3, 3))
    weights = np.array([0.2, 0.5, 0.3])
    n = 60_000
    rays = (np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3), np.float32),
            np.empty((n, 3), np.float32))
    aimed_rays(path, 0, np.cumsum(weights), low, extent, np.uint64(4), *rays)
    directions = rays[1]
    np.testing.assert_allclose(np.linalg.norm(directions, axis=1), 1.0)
    # the target of each ray: the axis its direction points along
    counts = np.bincount(np.argmax(directions, axis=1), minlength=3)
    assert stats.chisquare(counts, weights * n).pvalue > 1e-3


@pytest.mark.parametrize('targets', [12, 600])
def test_aimed_rays_take_the_target_of_their_first_draw(targets):
    # point targets (no extent) at (k + 1, 1, 0): a ray's direction tells its target; the
    # target is the first whose cumulative share exceeds the ray's first uniform draw (few
    # targets are counted, many searched)
    n = 20_000
    path = np.zeros((3, 3))
    low = np.stack([np.arange(1.0, targets + 1), np.ones(targets), np.zeros(targets)], axis=1)
    cumulative = np.cumsum(np.random.default_rng(targets).random(targets))
    cumulative /= cumulative[-1]
    rays = (np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3), np.float32),
            np.empty((n, 3), np.float32))
    aimed_rays(path, 0, cumulative, low, np.zeros((targets, 3)), np.uint64(9), *rays)
    target = np.rint(rays[1][:, 0] / rays[1][:, 1]).astype(int) - 1
    draws = _uniforms_every(np.uint64(9), 4, n)
    expected = np.minimum(np.searchsorted(cumulative, draws, side='right'), targets - 1)
    np.testing.assert_array_equal(target, expected)


@numba.njit
def _uniforms_every(seed: np.uint64, stride: int, count: int) -> np.ndarray:
    return np.array([uniform(seed, np.uint64(stride * k)) for k in range(count)])


def test_uniform_path_rays_are_uniform_on_the_sphere_and_go_round_the_path():
    n = 100_000
    path = np.arange(21.0).reshape(7, 3)
    rays = (np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3), np.float32),
            np.empty((n, 3), np.float32))
    path_rays(path, 3, np.uint64(5), *rays)
    origins, directions = rays[0], rays[1]
    np.testing.assert_array_equal(origins, path[(3 + np.arange(n)) % 7])
    np.testing.assert_allclose(np.linalg.norm(directions, axis=1), 1.0)
    # uniform on the sphere: the height uniform in [-1, 1] (Archimedes), the azimuth uniform
    assert stats.kstest((directions[:, 2] + 1) / 2, 'uniform').pvalue > 1e-3
    azimuth = np.arctan2(directions[:, 1], directions[:, 0])
    assert stats.kstest((azimuth + np.pi) / (2 * np.pi), 'uniform').pvalue > 1e-3
    np.testing.assert_array_equal(rays[2], origins.astype(np.float32))
    np.testing.assert_array_equal(rays[3], directions.astype(np.float32))
    again = tuple(np.empty_like(r) for r in rays)
    path_rays(path, 3, np.uint64(5), *again)
    np.testing.assert_array_equal(again[1], directions)


def test_tablet_returns_get_range_noise_of_the_configured_std():
    t_hit = np.full(200_000, 2.0, dtype=np.float32)
    t_hit[::5] = np.inf  # misses
    primitive = np.zeros(len(t_hit), dtype=np.uint32)
    rows, measured = tablet_returns(t_hit, primitive, np.uint64(3), np.zeros(1), 0.01, 1.0,
                                    0.3, 5.0, len(t_hit))
    assert len(rows) == np.isfinite(t_hit).sum()  # all kept: far_keep 1, no loss
    error = (measured - 2.0) / 0.01
    assert abs(error.mean()) < 0.02 and abs(error.std() - 1.0) < 0.02


def test_mixed_pixels_take_the_configured_share_of_the_edge_beams():
    # a grid of 200 x 300 beams: the room (part 0, 5 m) with an object (part 1, 2 m) in columns
    # 100-199: its two outlines are depth edges, 2 x 2 beams per row
    ranges = np.full((200, 300), 5.0)
    triangle = np.zeros((200, 300), dtype=np.int32)
    ranges[:, 100:200], triangle[:, 100:200] = 2.0, 1
    on_object, part = np.array([False, True]), np.array([0, 1])
    edges = depth_edges(ranges.reshape(-1), triangle.reshape(-1), 300, on_object, part, 0.1)[0]
    assert len(edges) == 200 * 4
    mixed, _, stray = mix_at_depth_edges(np.random.default_rng(6), ranges.copy(), triangle.copy(),
                                         on_object, part, 0.3, 0.1)
    assert set(np.flatnonzero(stray)) <= set(edges)
    assert abs(stray.sum() - 0.3 * len(edges)) < 4 * np.sqrt(0.3 * 0.7 * len(edges))
    # a mixed return lies between the two ranges, uniformly
    between = mixed[stray]
    assert between.min() > 2.0 and between.max() < 5.0
    assert stats.kstest((between - 2.0) / 3.0, 'uniform').pvalue > 1e-3


def test_tablet_rays_take_uniform_poses_and_pixels_and_the_kept_points_lie_on_them():
    n, poses = 100_000, 7
    positions = np.zeros((poses, 3))
    positions[:, 2] = np.arange(poses)  # the pose of a ray: its origin's height
    look = np.tile([1.0, 0.0, 0.0], (poses, 1))
    right, up = np.tile([0.0, -1.0, 0.0], (poses, 1)), np.tile([0.0, 0.0, 1.0], (poses, 1))
    half = np.array([0.5, 0.4])
    origins, directions = np.empty((n, 3), np.float32), np.empty((n, 3), np.float32)
    tablet_rays(positions, look, right, up, np.uint64(2), half, origins, directions)
    pose = origins[:, 2].astype(int)
    assert stats.chisquare(np.bincount(pose, minlength=poses)).pvalue > 1e-3
    # the pixel on the image plane at distance 1: (-y, z) / x, uniform within the half sizes
    across, above = -directions[:, 1] / directions[:, 0], directions[:, 2] / directions[:, 0]
    assert stats.kstest((across + 0.5) / 1.0, 'uniform').pvalue > 1e-3
    assert stats.kstest((above + 0.4) / 0.8, 'uniform').pvalue > 1e-3
    # the kept returns are drawn again in float64: the points lie on the cast rays, each with
    # its ray's pose and triangle
    rows = np.arange(0, n, 3)
    measured = np.linspace(0.5, 4.0, len(rows))
    primitive = np.arange(n, dtype=np.uint32)
    xyz, triangle, pose_of = np.empty((len(rows), 3)), np.empty(len(rows), np.int64), np.empty(
        len(rows), np.int64)
    tablet_points(positions, look, right, up, np.uint64(2), half, primitive, rows, measured, xyz,
                  triangle, pose_of)
    np.testing.assert_array_equal(pose_of, pose[rows])
    np.testing.assert_array_equal(triangle, rows)
    expected = origins[rows] + directions[rows].astype(np.float64) * measured[:, None]
    np.testing.assert_allclose(xyz, expected, atol=1e-6)


def _edge_rule(ranges: np.ndarray, triangle: np.ndarray, on_object: np.ndarray, part: np.ndarray,
               jump: float) -> list[tuple[int, float, int]]:
    """The depth edges of a grid (E, A) beam by beam, as documented: (beam, range, triangle)
    of the neighbour across the largest step."""
    rows, columns = ranges.shape
    found = []
    for row in range(rows):
        for column in range(columns):
            mine = ranges[row, column]
            if not np.isfinite(mine):
                continue
            largest, best = 0.0, None
            neighbours = [(row, (column - 1) % columns), (row, (column + 1) % columns)]
            neighbours += [(r, column) for r in (row - 1, row + 1) if 0 <= r < rows]
            for r, c in neighbours:
                gap = abs(ranges[r, c] - mine)
                if not (jump < gap < np.inf and gap > largest):
                    continue
                theirs, own = triangle[r, c], triangle[row, column]
                if (on_object[own] or on_object[theirs]) and part[theirs] != part[own]:
                    largest, best = gap, (row * columns + column, ranges[r, c], theirs)
            if best is not None:
                found.append(best)
    return found


def test_depth_edges_follow_the_edge_rule_beam_by_beam():
    # a random grid with lost beams, three parts (two objects), steps of all sizes
    rng = np.random.default_rng(4)
    ranges = rng.choice([1.0, 1.05, 2.0, 3.5], (13, 17)) + rng.uniform(0, 0.04, (13, 17))
    ranges[rng.random((13, 17)) < 0.15] = np.inf
    triangle = rng.integers(0, 6, (13, 17)).astype(np.int32)
    on_object, part = np.array([False, False, True, True, True, False]), np.array([0, 0, 1, 1, 2,
                                                                                   0])
    edges, other, other_tri = depth_edges(ranges.reshape(-1), triangle.reshape(-1), 17,
                                          on_object, part, 0.1)
    expected = _edge_rule(ranges, triangle, on_object, part, 0.1)
    assert len(expected) > 20
    assert list(zip(edges.tolist(), other.tolist(), other_tri.tolist())) == expected


@numba.njit
def _beam_draws(seed: np.uint64, count: int) -> np.ndarray:
    return np.array([normal(seed, np.uint64(256 * k + 1)) for k in range(count)])


def test_range_noise_is_each_beams_own_normal_draw():
    # chunks of beams draw the first tries apart from the rest: each beam still gets the
    # normal draw of its own counters
    ranges = np.random.default_rng(2).uniform(0.5, 9.0, 10_000)
    ranges[::9] = np.inf
    noisy = ranges.copy()
    add_range_noise(noisy, np.uint64(21), 0.002, 0.0005)
    finite = np.isfinite(ranges)
    draws = _beam_draws(np.uint64(21), len(ranges))
    np.testing.assert_array_equal(noisy[finite], ranges[finite] + draws[finite] *
                                  (0.002 + 0.0005 * ranges[finite]))
    assert (np.abs(draws) > 3.442619855899).sum() > 0  # draws past the ziggurat's first try


def test_grid_points_of_beams_in_any_order():
    angles = angle_tables(*tls_grid(3.0, -60.0))
    station = np.array([1.0, -2.0, 1.5])
    beams = np.random.default_rng(5).permutation(len(angles[0]) * len(angles[2]))[:3000]
    measured = np.linspace(1.0, 7.0, len(beams))
    row, column = np.divmod(beams, len(angles[2]))
    direction = np.stack([angles[0][row] * angles[2][column], angles[0][row] * angles[3][column],
                          angles[1][row]], axis=1)
    np.testing.assert_allclose(grid_points(station, *angles, beams, measured),
                               station + direction * measured[:, None], atol=1e-12)


def test_tls_returns_do_not_depend_on_the_slices_of_the_cast():
    from tests.test_generator.test_generator_sensors import objects, room_scene
    scanner = Scanner(room_scene((6.0, 5.0, 3.0), [((2, 2, 0), (3, 3, 1), (200, 0, 0))]), 1,
                      [(200, 0, 0)], 0.5)
    station = np.array([[4.0, 1.5, 1.4]])
    cfg = DEFAULTS['scanner']['tls']
    assert scanner.slice_size(700) == 700 and scanner.slice_size(10**6) == 32768
    small, large = (cast_tls(scanner, station, 1.5, np.random.default_rng(3), cfg, batch,
                             objects(scanner)) for batch in (700, 10**6))
    for a, b in zip(small, large):
        np.testing.assert_array_equal(a, b)


@numba.njit
def _ray_draws(seed: np.uint64, count: int) -> tuple[np.ndarray, np.ndarray]:
    errors = np.array([normal(seed, np.uint64(256 * k + 4)) for k in range(count)])
    keeps = np.array([uniform(seed, np.uint64(256 * k + 3)) for k in range(count)])
    return errors, keeps


@pytest.mark.parametrize('most', [10**6, 3000])
def test_tablet_returns_follow_the_keep_rule_ray_by_ray(most):
    rng = np.random.default_rng(6)
    t_hit = rng.uniform(0.1, 6.0, 20_000).astype(np.float32)
    t_hit[rng.random(len(t_hit)) < 0.1] = np.inf
    primitive = rng.integers(0, 50, len(t_hit)).astype(np.uint32)
    loss = rng.choice([0.0, 0.3, 0.7], 50)
    rows, measured = tablet_returns(t_hit, primitive, np.uint64(8), loss, 0.05, 0.3, 0.3, 5.0,
                                    most)
    errors, keeps = _ray_draws(np.uint64(8), len(t_hit))
    distance = t_hit.astype(np.float64) + errors * 0.05
    chance = (1.0 - 0.7 * (distance - 0.3) / 4.7) * (1.0 - loss[primitive])
    expected = np.flatnonzero(np.isfinite(t_hit) & (distance >= 0.3) & (distance <= 5.0) &
                              (keeps < chance))[:most]
    np.testing.assert_array_equal(rows, expected)
    np.testing.assert_array_equal(measured, distance[expected])

