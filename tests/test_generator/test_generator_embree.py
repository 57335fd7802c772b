"""Embree called from compiled code (generator.embree): the same first hits as embreex's ``run``
(the binding that ships the library), independent of the batch, the threads and the packets."""
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest
from embreex.mesh_construction import TriangleMesh
from embreex.rtcore_scene import EmbreeScene

from generator.embree import TriangleMeshScene, first_hits

REPO = Path(__file__).resolve().parents[2]


def _room_with_soup(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A closed 6 x 4 x 3 m box (12 triangles, shared edges) and 400 small random triangles
    inside it: vertices (V, 3) float64, triangles (T, 3)."""
    corners = np.array([[x, y, z] for x in (0.0, 6.0) for y in (0.0, 4.0) for z in (0.0, 3.0)])
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    box = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    rng = np.random.default_rng(seed)
    centres = rng.uniform([0.5, 0.5, 0.5], [5.5, 3.5, 2.5], (400, 1, 3))
    soup = (centres + rng.uniform(-0.3, 0.3, (400, 3, 3))).reshape(-1, 3)
    vertices = np.concatenate([corners, soup])
    triangles = np.concatenate([box, 8 + np.arange(len(soup)).reshape(-1, 3)])
    return vertices, triangles


def _embreex_hits(vertices: np.ndarray, triangles: np.ndarray, origins: np.ndarray,
                  directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """embreex's first hits of the same rays in Embree's default (non-robust) mode."""
    scene = EmbreeScene(robust=False)
    TriangleMesh(scene, vertices.astype(np.float32), triangles.astype(np.int32))
    answer = scene.run(origins, directions, dists=np.full(len(origins), np.inf, np.float32),
                       output=1)
    return answer['tfar'], answer['primID']


def _rays(count: int, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """float32 rays: half random from inside the room, a quarter from outside (most miss), a
    quarter a coherent sweep of directions from one point, as a laser scanner's grid."""
    rng = np.random.default_rng(seed)
    inside = count // 2
    outside = count // 4
    sweep = count - inside - outside
    origins = np.concatenate([
        rng.uniform([0.2, 0.2, 0.2], [5.8, 3.8, 2.8], (inside, 3)),
        rng.uniform([-4.0, -4.0, -4.0], [-1.0, -1.0, -1.0], (outside, 3)),
        np.tile([[3.0, 2.0, 1.5]], (sweep, 1)),
    ])
    azimuth = np.linspace(0, 2 * np.pi, sweep, endpoint=False)
    elevation = np.linspace(-1.2, 1.2, sweep)
    directions = np.concatenate([
        rng.normal(size=(inside + outside, 3)),
        np.stack([np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth),
                  np.sin(elevation)], axis=1),
    ])
    return origins.astype(np.float32), directions.astype(np.float32)


def test_first_hits_are_embreex_hits_bit_for_bit():
    """Random, outside (mostly missing) and coherent rays, 10,003 of them (the last packet has 3
    rays): the same distances and triangles as embreex, inf and -1 for a miss."""
    vertices, triangles = _room_with_soup()
    origins, directions = _rays(10_003)
    t_hit, primitive = first_hits(TriangleMeshScene(vertices, triangles), origins, directions)
    expected_t, expected_primitive = _embreex_hits(vertices, triangles, origins, directions)
    assert t_hit.dtype == np.float32 and primitive.dtype == np.int32
    assert np.array_equal(t_hit, expected_t) and np.array_equal(primitive, expected_primitive)
    missed = np.isinf(t_hit)
    assert 500 < missed.sum() < 2500 and np.all(primitive[missed] == -1)
    assert np.all(primitive[~missed] >= 0) and np.all(primitive[~missed] < len(triangles))
    # a ray's hit is its own: casting every tail length alone gives the same hits
    scene = TriangleMeshScene(vertices, triangles)
    for start in range(10_003 - 17, 10_003):
        alone = first_hits(scene, origins[start:], directions[start:])
        assert np.array_equal(alone[0], t_hit[start:])
        assert np.array_equal(alone[1], primitive[start:])


def test_first_hits_into_given_outputs_on_threads():
    """Threads casting slices of one batch into their parts of the outputs give the hits of one
    call; strided (broadcast) origins are read as they are."""
    vertices, triangles = _room_with_soup(2)
    scene = TriangleMeshScene(vertices, triangles)
    origins, directions = _rays(40_001, seed=3)
    whole = first_hits(scene, origins, directions)
    t_hit, primitive = np.empty(40_001, np.float32), np.empty(40_001, np.int32)
    edges = [0, 9_999, 20_000, 33_331, 40_001]

    def cast(start: int, stop: int) -> None:
        first_hits(scene, origins[start:stop], directions[start:stop], t_hit[start:stop],
                   primitive[start:stop])

    with ThreadPoolExecutor(4) as pool:
        list(pool.map(cast, edges[:-1], edges[1:]))
    assert np.array_equal(t_hit, whole[0]) and np.array_equal(primitive, whole[1])
    station = np.broadcast_to(np.float32([3.0, 2.0, 1.5]), directions.shape)
    from_station = first_hits(scene, station, directions)
    assert np.array_equal(from_station[0], first_hits(scene, station.copy(), directions)[0])


def test_empty_batches_and_scenes():
    """No rays: empty outputs; a scene without triangles: every ray misses."""
    vertices, triangles = _room_with_soup()
    t_hit, primitive = first_hits(TriangleMeshScene(vertices, triangles), np.zeros((0, 3)),
                                  np.zeros((0, 3)))
    assert t_hit.shape == (0,) and primitive.shape == (0,)
    empty = TriangleMeshScene(vertices, np.zeros((0, 3), np.int64))
    t_hit, primitive = first_hits(empty, np.zeros((5, 3)), np.ones((5, 3)))
    assert np.isinf(t_hit).all() and np.all(primitive == -1)


def test_bad_arguments_are_named():
    vertices, triangles = _room_with_soup()
    with pytest.raises(ValueError, match=r'triangles index vertices outside 0\.\.7'):
        TriangleMeshScene(vertices[:8], triangles)
    with pytest.raises(ValueError, match=r'vertices must be \(V, 3\), not \(5, 2\)'):
        TriangleMeshScene(np.zeros((5, 2)), triangles)
    scene = TriangleMeshScene(vertices, triangles)
    with pytest.raises(ValueError, match=r'both be \(N, 3\), not \(4, 3\) and \(3, 3\)'):
        first_hits(scene, np.zeros((4, 3)), np.ones((3, 3)))
    with pytest.raises(ValueError, match='float32 and int32 arrays of 4 rays, not float64'):
        first_hits(scene, np.zeros((4, 3)), np.ones((4, 3)), np.empty(4), np.empty(4, np.int32))


def test_a_missing_or_broken_library_is_named(tmp_path):
    """The library is looked up beside the installed embreex package: a package without it, or
    a file that is no library, gives an error naming the folder or the file."""
    package = tmp_path / 'embreex'
    package.mkdir()
    (package / '__init__.py').write_text('')
    libs = tmp_path.resolve() / 'embreex.libs'
    libs.mkdir()
    script = ('from generator.embree import EmbreeError, TriangleMeshScene\n'
              'try:\n'
              '    TriangleMeshScene([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])\n'
              'except EmbreeError as error:\n'
              '    print(error)\n')

    def run() -> str:
        done = subprocess.run([sys.executable, '-c', script], cwd=REPO, capture_output=True,
                              text=True, timeout=120,
                              env=dict(os.environ, PYTHONPATH=f'{tmp_path}:{REPO}'))
        assert done.returncode == 0, done.stderr
        return done.stdout.strip()

    assert run() == f'{libs}: no libembree4*.so* (the embreex wheel ships Embree 4 there)'
    (libs / 'libembree4.so.4').write_text('not a library')
    assert run().startswith(f'{libs / "libembree4.so.4"}: cannot be loaded: ')
