"""What every scan format shares: the error type, bounded line reading and color scaling.

Text is read a block of whole lines at a time, never a line longer than ``MAX_LINE_BYTES``, so
memory stays bounded whatever the file holds. ``MAX_LINE_BYTES`` is read when a file is read:
changing it here changes it for every format.
"""
from __future__ import annotations

import io
import math
import re
from pathlib import Path
from typing import Callable, Iterator

import numba
import numpy as np

CHUNK_POINTS = 1_000_000  # default points per chunk: about 50 MB of float64 rows
MAX_LINE_BYTES = 1 << 20  # longest text line read (1 MiB); a longer one is refused
TEXT_BYTES_PER_POINT = 48  # text blocks hold about this many bytes per chunk point


class ScanFormatError(ValueError):
    """A scan file that is empty, malformed, holds non-finite values or looks mis-scaled."""


# a format's reader: reader(path, chunk_points, columns, notes) yields (n, 6) float64 chunks
ChunkReader = Callable[[Path, int, 'tuple[str, ...] | None', list], Iterator[np.ndarray]]


def grey(intensity: np.ndarray) -> np.ndarray:
    """``(n, 3)`` grey colors of intensities already scaled to 0-255."""
    level = np.clip(intensity, 0.0, 255.0)
    return np.repeat(level[:, None], 3, axis=1)


class Scale:
    """Maps raw color or intensity values to 0-255 with a range fixed by the first chunk.

    The range is the header's when known, else the smallest usual one holding the first
    chunk's values: [0, 1] (float), 0-255 (8 bit), 0-4095 (12 bit), 0-65535 (16 bit), or
    -2048-2047 (PTS intensity); every chunk then uses that range, so chunks agree.
    """

    def __init__(self, low: float | None = None, high: float | None = None):
        self.low, self.high = low, high

    def __call__(self, values: np.ndarray) -> np.ndarray:
        values = np.asarray(values, dtype=np.float64)
        if self.high is None and len(values):
            low, high = float(values.min()), float(values.max())
            if low < 0:
                self.low, self.high = -2048.0, 2047.0
            else:
                self.low = 0.0
                self.high = next(
                    top for top in (1.0, 255.0, 4095.0, 65535.0, math.inf) if high <= top)
                if math.isinf(self.high):
                    self.high = high
        if self.high is None or self.high <= self.low:
            return np.zeros_like(values)
        return np.clip((values - self.low) * (255.0 / (self.high - self.low)), 0.0, 255.0)


def structured_chunk(part: np.ndarray, colors: np.ndarray | None, intensity: str | None,
                     intensity_scale: Scale) -> np.ndarray:
    """``(n, 6)`` rows of the structured array ``part``: its ``x y z`` fields, then ``colors``
    (0-255) or, without them, its field ``intensity`` scaled as grey (zeros without either)."""
    chunk = np.zeros((len(part), 6))
    for i, name in enumerate('xyz'):
        chunk[:, i] = part[name]
    if colors is not None:
        chunk[:, 3:] = colors
    elif intensity is not None:
        chunk[:, 3:] = grey(intensity_scale(part[intensity]))
    return chunk


def no_color_note(path: Path, has_intensity: bool) -> str:
    """The note for a scan without colors: what the model gets instead."""
    if has_intensity:
        return f'{path}: no colors: the model gets the intensity as grey instead'
    return f'{path}: no colors and no intensity: the model gets zeros (black) instead'


_SPLIT = {',': b',', ';': b';', ' ': None}
NUMBER = re.compile(rb'^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$')
NON_FINITE = re.compile(rb'^[+-]?(nan|inf|infinity)$', re.IGNORECASE)


def split_tokens(line: bytes, delimiter: str) -> list[bytes]:
    """The values of a text line split at ``delimiter`` (``' '``: any run of blanks)."""
    return [
        token.strip() for token in line.split(_SPLIT[delimiter])
        if token.strip() or delimiter != ' '
    ]


def long_line_error(path: Path, number: int) -> ScanFormatError:
    """The error for line ``number`` of ``path`` being longer than ``MAX_LINE_BYTES``."""
    return ScanFormatError(f'{path}:{number}: line longer than {MAX_LINE_BYTES:,} bytes; a '
                           f'text scan holds one point a line')


def read_line(stream: io.BufferedReader, path: Path, number: int) -> bytes:
    """The next line (line ``number`` of the file), read no further than ``MAX_LINE_BYTES``."""
    line = stream.readline(MAX_LINE_BYTES + 1)
    if len(line) > MAX_LINE_BYTES and not line.endswith(b'\n'):
        raise long_line_error(path, number)
    return line


@numba.njit(cache=True, nogil=True)
def _first_long_line(text: np.ndarray, limit: int) -> int:
    """Index of the first line of ``text`` (uint8) longer than ``limit`` bytes, or -1."""
    start = 0
    line = 0
    for i in range(text.shape[0]):
        if text[i] == 10:
            if i - start > limit:
                return line
            start = i + 1
            line += 1
    return line if text.shape[0] - start > limit else -1


def text_blocks(path: Path, skip: int, chunk_points: int) -> Iterator[tuple[int, bytes]]:
    """Blocks of whole lines, about ``TEXT_BYTES_PER_POINT * chunk_points`` bytes each, after
    ``skip`` header lines, with the 1-based number of each block's first line.

    Memory stays one block plus one line: a line longer than ``MAX_LINE_BYTES`` raises
    ``ScanFormatError`` naming the file and the line, wherever it is.
    """
    block_bytes = TEXT_BYTES_PER_POINT * chunk_points
    with open(path, 'rb') as stream:
        for number in range(1, skip + 1):
            read_line(stream, path, number)
        number, rest = skip + 1, b''
        while True:
            data = stream.read(block_bytes)
            if data and b'\n' not in data:  # the line goes on: keep it, up to the limit
                rest += data
                if len(rest) > MAX_LINE_BYTES:
                    raise long_line_error(path, number)
                continue
            cut = data.rfind(b'\n') + 1 if data else len(rest)
            block, rest = rest + data[:cut], data[cut:]
            if len(block) > MAX_LINE_BYTES:
                long = _first_long_line(np.frombuffer(block, dtype=np.uint8), MAX_LINE_BYTES)
                if long >= 0:
                    raise long_line_error(path, number + long)
            if block:
                yield number, block
                number += block.count(b'\n')
            if not data:
                return


def token_problem(tokens: list[bytes]) -> str | None:
    """What is wrong with the first token of a line that is not a finite number, or None."""
    for token in tokens:
        if not NUMBER.match(token):
            text = token.decode(errors='replace')[:40]
            if NON_FINITE.match(token):
                return f'non-finite value {text!r} (values must be finite numbers)'
            return f'cannot read {text!r} as a number'
    return None


def bad_line(block: bytes, count: int, delimiter: str) -> tuple[int, str]:
    """Offset in the block of its first line that is not ``count`` finite numbers, and what is
    wrong with it (``(0, '')`` if every line is good)."""
    for offset, line in enumerate(block.split(b'\n')):
        tokens = split_tokens(line, delimiter)
        if not tokens:
            continue
        problem = token_problem(tokens)
        if problem is None and len(tokens) != count:
            problem = f'expected {count} values per line, found {len(tokens)}'
        if problem is not None:
            return offset, problem
    return 0, ''


def one_line(error: Exception) -> str:
    """An exception's message on one line, without numpy's advice on its own arguments
    (``use `usecols` to select a subset``), which a user reading a scan cannot follow."""
    return ' '.join(str(error).split('; use `usecols`')[0].split())


def colors_0_255(points: np.ndarray) -> np.ndarray:
    """The colors of ``(N, 6)`` points as whole numbers 0-255, for writing."""
    return np.clip(np.rint(points[:, 3:6]), 0, 255).astype(np.int64)
