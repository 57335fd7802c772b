"""Counter-based random numbers for numba kernels: the draw number ``counter`` of a stream
``seed`` is a pure function of the two, so a kernel draws for each beam or return where it needs
one (in any order, only for the items it keeps) and a later pass can draw the same number again.

A word is SplitMix64's output at step ``counter + 1`` of the state ``seed``: the state advanced by
that many times the golden-ratio increment, through SplitMix64's finalising mix (a generator
that passes TestU01's BigCrush). Uniforms take a word's top 53 bits; standard normals come from
a 128-layer ziggurat (Marsaglia and Tsang's method in Doornik's formulation: one word per draw
in about 99 % of draws, exact rejection in the layers' wedges and the tail).
"""
import math

import numba
import numpy as np

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX_1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX_2 = np.uint64(0x94D049BB133111EB)
_UNIT = 2.0**-53

# the ziggurat: 128 layers of equal area, the bottom one with the tail beyond _TAIL_START
_LAYERS = 128
_TAIL_START = 3.442619855899
_LAYER_AREA = 9.91256303526217e-3

# counters per item (beam, ray) of a stream that gives each item a few uniform words and then
# one normal draw: the item's words start at item x ITEM_COUNTERS, and its normal draw has the
# rest of them (one word in about 99 % of draws, see :func:`normal`)
ITEM_COUNTERS = np.uint64(256)


def _ziggurat_tables() -> tuple[np.ndarray, np.ndarray]:
    """The layers' right edges x (LAYERS + 1,), x[0] the bottom layer's width as a rectangle of
    its area, x[LAYERS] = 0, and the share of each layer inside the next one's edge."""
    edges = np.zeros(_LAYERS + 1)
    density = math.exp(-0.5 * _TAIL_START**2)
    edges[0], edges[1] = _LAYER_AREA / density, _TAIL_START
    for layer in range(2, _LAYERS):
        edges[layer] = math.sqrt(-2.0 * math.log(_LAYER_AREA / edges[layer - 1] + density))
        density = math.exp(-0.5 * edges[layer]**2)
    return edges, edges[1:] / edges[:-1]


_EDGES, _INSIDE = _ziggurat_tables()


@numba.njit(cache=True, nogil=True)
def word(seed: np.uint64, counter: np.uint64) -> np.uint64:
    """The 64 random bits number ``counter`` of stream ``seed``."""
    z = seed + (counter + np.uint64(1)) * _GOLDEN
    z = (z ^ (z >> np.uint64(30))) * _MIX_1
    z = (z ^ (z >> np.uint64(27))) * _MIX_2
    return z ^ (z >> np.uint64(31))


@numba.njit(cache=True, nogil=True)
def uniform(seed: np.uint64, counter: np.uint64) -> float:
    """A uniform draw in [0, 1): the top 53 bits of word ``counter``."""
    return np.float64(word(seed, counter) >> np.uint64(11)) * _UNIT


@numba.njit(cache=True, nogil=True)
def _open_uniform(seed: np.uint64, counter: np.uint64) -> float:
    """A uniform draw in (0, 1), for a logarithm."""
    return (np.float64(word(seed, counter) >> np.uint64(11)) + 0.5) * _UNIT


@numba.njit(cache=True, nogil=True, inline='always')
def _ziggurat_try(bits: np.uint64) -> tuple[float, float, int]:
    """One try of the ziggurat with a word: the position u in (-1, 1) (from the top 53 bits,
    with the sign), the value u x the layer's edge, and the layer (the lowest 7 bits)."""
    layer = np.int64(bits & np.uint64(_LAYERS - 1))
    u = 2.0 * (np.float64(bits >> np.uint64(11)) * _UNIT) - 1.0
    return u, u * _EDGES[layer], layer


@numba.njit(cache=True, nogil=True, inline='always')
def normal_first_try(seed: np.uint64, counter: np.uint64) -> tuple[float, bool]:
    """The first try of :func:`normal` at ``counter``, without a branch: its value and whether
    it is the draw (in about 99 % of draws; else :func:`normal` gives the draw). A kernel
    makes the first tries of many items in one pass and calls :func:`normal` for the rest
    (:func:`normals`)."""
    u, value, layer = _ziggurat_try(word(seed, counter))
    return value, abs(u) < _INSIDE[layer]


@numba.njit(cache=True, nogil=True)
def normal(seed: np.uint64, counter: np.uint64) -> float:
    """A standard normal draw from the words ``counter``, ``counter + 1``, ... of stream
    ``seed`` (the first only, but for about 1 % of draws; a caller gives each draw its own
    range of counters, as :data:`ITEM_COUNTERS` does)."""
    while True:
        u, value, layer = _ziggurat_try(word(seed, counter))
        counter += np.uint64(1)
        if abs(u) < _INSIDE[layer]:
            return value
        if layer == 0:  # the tail beyond _TAIL_START (Marsaglia's method)
            while True:
                x = math.log(_open_uniform(seed, counter)) / _TAIL_START
                y = math.log(_open_uniform(seed, counter + np.uint64(1)))
                counter += np.uint64(2)
                if -2.0 * y >= x * x:
                    return x - _TAIL_START if u < 0 else _TAIL_START - x
        x = u * _EDGES[layer]
        # the density at the layer's bottom and top, relative to the density at x
        bottom = math.exp(-0.5 * (_EDGES[layer]**2 - x * x))
        top = math.exp(-0.5 * (_EDGES[layer + 1]**2 - x * x))
        if bottom + uniform(seed, counter) * (top - bottom) < 1.0:
            return x
        counter += np.uint64(1)


def stream_seed(rng: np.random.Generator) -> np.uint64:
    """A stream's seed drawn from ``rng``."""
    return np.uint64(rng.integers(0, 2**64, dtype=np.uint64))


# items whose normal draws a kernel makes at a time with :func:`normals` (a buffer that stays
# in the cache)
DRAW_CHUNK = 2048


@numba.njit(cache=True, nogil=True, inline='always')
def normals(seed: np.uint64, first: int, stop: int, offset: int, out: np.ndarray) -> None:
    """The standard normal draws of the items ``first`` to ``stop - 1`` into
    ``out[:stop - first]``, item k's as :func:`normal` gives it from the counter
    ``k * ITEM_COUNTERS + offset``: the first tries of all in one pass without branches (a
    failed one written as NaN), then :func:`normal` for those, about 1 %."""
    for item in range(first, stop):
        value, accepted = normal_first_try(
            seed, np.uint64(item) * ITEM_COUNTERS + np.uint64(offset))
        out[item - first] = value if accepted else np.nan
    for item in range(first, stop):
        if np.isnan(out[item - first]):
            out[item - first] = normal(seed, np.uint64(item) * ITEM_COUNTERS + np.uint64(offset))
