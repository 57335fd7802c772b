"""Point text files (one ``x y z r g b`` line per point, as S3DIS): the project's one parser and
its fast writer.

A compiled fast path parses well-formed files. Whenever it meets anything it does not
handle (a bad line, an exotic number, a color out of range), the file is read again by a
line-by-line reference parser that decides what is valid and names the offending line.
Both parsers round decimal text to the nearest float64, so their results are identical.
Files of ``x y z`` lines (no colors) are read with ``columns=3``.
"""
import re
from dataclasses import dataclass
from pathlib import Path

import numba
import numpy as np

NUM_COLUMNS = 6
COLUMN_CHOICES = (3, 6)  # x y z, or x y z r g b
_NUMBER = re.compile(rb'[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?')
_POW10 = np.array([10.0**k for k in range(23)])  # exactly representable powers of ten
_MAX_DIGITS = 18  # a mantissa of up to 18 digits fits in int64 ...
_MAX_EXACT_MANTISSA = 2**53  # ... and is exact in float64 up to 2**53
_COLUMN_NAMES = {3: 'x y z', 6: 'x y z r g b'}


class PointFileError(ValueError):
    """A point text file is malformed; the message names the file and the line."""

    def __init__(self, path: Path, line: int, reason: str):
        super().__init__(f'{path}:{line}: {reason}')
        self.path, self.line, self.reason = path, line, reason

    def __reduce__(self):  # keeps the fields when raised in a worker process
        return PointFileError, (self.path, self.line, self.reason)


@dataclass
class BadLine:
    """A line that was skipped, with the reason."""
    path: Path
    line: int
    reason: str


def parse_fast(buf: np.ndarray, out: np.ndarray) -> tuple[int, int]:
    """Parse rows of ``out.shape[1]`` decimal numbers (columns 3-5, the colors, within 0-255)
    from the bytes ``buf`` (uint8) into ``out`` with the compiled fast path.

    Returns (rows, 0) on success or (-1, line) at the first line it cannot handle.
    """
    return _parse_rows(buf, out, _POW10)


@numba.njit(cache=True, nogil=True)
def _parse_rows(buf: np.ndarray, out: np.ndarray, pow10: np.ndarray) -> tuple[int, int]:
    """:func:`parse_fast` with the table of exact powers of ten."""
    n = buf.shape[0]
    columns = out.shape[1]
    i = 0
    row = 0
    line = 1
    while i < n:
        while i < n and (buf[i] == 32 or buf[i] == 9 or buf[i] == 13):
            i += 1
        if i >= n:
            break
        if buf[i] == 10:  # blank line
            i += 1
            line += 1
            continue
        col = 0
        while True:
            value, i, handled = _parse_number(buf, i, pow10)
            if not handled or col >= columns or row >= out.shape[0]:
                return -1, line
            if col >= 3 and not 0.0 <= value <= 255.0:
                return -1, line
            out[row, col] = value
            col += 1
            if i < n and not (buf[i] == 32 or buf[i] == 9 or buf[i] == 13 or buf[i] == 10):
                return -1, line
            while i < n and (buf[i] == 32 or buf[i] == 9 or buf[i] == 13):
                i += 1
            if i >= n or buf[i] == 10:
                break
        if col != columns:
            return -1, line
        row += 1
        i += 1
        line += 1
    return row, 0


@numba.njit(cache=True, nogil=True)
def _parse_number(buf: np.ndarray, i: int, pow10: np.ndarray) -> tuple[float, int, bool]:
    """The decimal number starting at ``buf[i]``: its value, the index after it and whether
    the fast path handles it (at most 18 exact mantissa digits, a power of ten within 1e22)."""
    n = buf.shape[0]
    negative = False
    if buf[i] == 45 or buf[i] == 43:  # '-' or '+'
        negative = buf[i] == 45
        i += 1
    mantissa = 0
    digits = 0
    exponent = 0
    while i < n and 48 <= buf[i] <= 57:
        mantissa = mantissa * 10 + (buf[i] - 48)
        digits += 1
        i += 1
    if i < n and buf[i] == 46:  # '.'
        i += 1
        start = i
        while i < n and 48 <= buf[i] <= 57:
            mantissa = mantissa * 10 + (buf[i] - 48)
            i += 1
        digits += i - start
        exponent = start - i
    if digits == 0 or digits > _MAX_DIGITS or mantissa > _MAX_EXACT_MANTISSA:
        return 0.0, i, False
    if i < n and (buf[i] == 101 or buf[i] == 69):  # 'e' or 'E'
        i += 1
        exp_negative = False
        if i < n and (buf[i] == 45 or buf[i] == 43):
            exp_negative = buf[i] == 45
            i += 1
        exp_value = 0
        exp_digits = 0
        while i < n and 48 <= buf[i] <= 57 and exp_value < 1000:
            exp_value = exp_value * 10 + (buf[i] - 48)
            exp_digits += 1
            i += 1
        if exp_digits == 0:
            return 0.0, i, False
        exponent += -exp_value if exp_negative else exp_value
    if exponent > 22 or exponent < -22:
        return 0.0, i, False
    # one correctly rounded operation on exact operands: nearest float64 of the text
    value = float(mantissa) * pow10[exponent] if exponent >= 0 else \
        float(mantissa) / pow10[-exponent]
    return (-value if negative else value), i, True


def _describe_bad_token(token: bytes) -> str:
    text = token.decode(errors='replace')
    try:
        if not np.isfinite(float(text)):
            return f'non-finite value {text!r}'
    except ValueError:
        pass
    return f'cannot parse {text!r} as a number'


def _check_row(values: list[float], tokens: list[bytes]) -> str | None:
    for value, token in zip(values, tokens):
        if not np.isfinite(value):
            return f'non-finite value {token.decode(errors="replace")!r}'
    for value in values[3:]:
        if not 0.0 <= value <= 255.0:
            return f'color value {value:g} outside 0-255'
    return None


def _parse_reference(path: Path,
                     data: bytes,
                     skip_bad_lines: bool,
                     columns: int,
                     first_line: int = 1) -> tuple[np.ndarray, list[BadLine]]:
    """Line-by-line parser that defines what is valid; raises or records each bad line.
    ``data`` starts at line ``first_line`` of the file."""
    rows: list[list[float]] = []
    bad_lines: list[BadLine] = []
    for line_no, line in enumerate(data.split(b'\n'), start=first_line):
        tokens = line.split()
        if not tokens:
            continue
        bad = [t for t in tokens if not _NUMBER.fullmatch(t)]
        if bad:
            reason = _describe_bad_token(bad[0])
        elif len(tokens) != columns:
            reason = f'expected {columns} columns ({_COLUMN_NAMES[columns]}), found {len(tokens)}'
        else:
            values = [float(t) for t in tokens]
            reason = _check_row(values, tokens)
        if reason is None:
            rows.append(values)
        elif skip_bad_lines:
            bad_lines.append(BadLine(path, line_no, reason))
        else:
            raise PointFileError(path, line_no, reason)
    return np.array(rows, dtype=np.float64).reshape(-1, columns), bad_lines


def compile_parser() -> None:
    """Compile (or load from numba's cache) the fast parser, e.g. before forking workers."""
    parse_fast(np.frombuffer(b'', dtype=np.uint8), np.empty((1, NUM_COLUMNS)))


def max_rows(num_bytes: int, columns: int = NUM_COLUMNS) -> int:
    """Upper bound of the rows in a file of num_bytes: a row takes at least "0 0 0 0 0 0\\n"
    (two bytes a column)."""
    return num_bytes // (2 * columns) + 1


def read_point_file(path: str | Path,
                    skip_bad_lines: bool = False,
                    out: np.ndarray | None = None,
                    columns: int = NUM_COLUMNS,
                    data: bytes | None = None) -> tuple[np.ndarray, list[BadLine]]:
    """Read an ``x y z r g b`` text file into a float64 (N, 6) array (``columns=3``: ``x y z``
    lines into (N, 3)).

    Bad lines (wrong column count, unparsable or non-finite numbers, colors outside 0-255)
    raise :class:`PointFileError` naming file and line, or are skipped and returned as
    :class:`BadLine` records when ``skip_bad_lines`` is set. Blank lines are ignored. A file
    without any point is an error in both modes, reported as line 1.

    With ``out`` (C-contiguous float64, at least ``max_rows(file size)`` x ``columns``), the
    points are written to its first rows and the returned array is a view of them. ``data``
    parses these bytes (e.g. a repaired copy of the file) instead of reading ``path``, which
    still names the file in errors.
    """
    if columns not in COLUMN_CHOICES:
        raise ValueError(f'columns must be one of {COLUMN_CHOICES}, got {columns}')
    path = Path(path)
    data = path.read_bytes() if data is None else data
    if out is None:
        out = np.empty((max_rows(len(data), columns), columns))  # untouched pages cost nothing
    elif len(out) < max_rows(len(data), columns) or out.shape[1] != columns:
        raise ValueError(f'{path}: output array of shape {out.shape} is too small')
    rows, _ = parse_fast(np.frombuffer(data, dtype=np.uint8), out)
    bad_lines: list[BadLine] = []
    if rows < 0:
        points, bad_lines = _parse_reference(path, data, skip_bad_lines, columns)
        rows = len(points)
        out[:rows] = points
    if rows == 0:
        reason = 'file is empty (no points)' if not bad_lines else 'no valid point line'
        raise PointFileError(path, 1, reason)
    return out[:rows], bad_lines


# --------------------------------------------------------------------------- writing


def _digit_table(count: int, width: int) -> np.ndarray:
    """ASCII digits of 0..count-1, right-aligned in ``width`` columns, 0 bytes as left padding."""
    values = np.arange(count)
    table = np.zeros((count, width), dtype=np.uint8)
    n_digits = 1 + sum((values >= 10**k).astype(np.int64) for k in range(1, width + 1))
    for col in range(width):
        power = width - 1 - col
        table[:, col] = np.where(n_digits > power, 48 + (values // 10**power) % 10, 0)
    return table


_COLOR_DIGITS = _digit_table(256, 3)


def format_lines(xyz: np.ndarray, rgb: np.ndarray, decimals: int = 3) -> tuple[bytes, np.ndarray]:
    """Format points as 'x y z r g b' lines; return the bytes and the (N+1,) line start offsets.

    ``x`` is printed as ``round(x * 10**decimals)`` scaled back, so parsing the text gives
    ``np.rint(x * 10**decimals) / 10**decimals`` exactly. Digits come from lookup tables.
    """
    n = len(xyz)
    scale = 10**decimals
    fraction_digits = _digit_table(scale, decimals)
    fraction_digits[fraction_digits == 0] = 48  # fractions keep their leading zeros
    quantised = np.rint(np.asarray(xyz, dtype=np.float64) * scale).astype(np.int64)
    whole_max = int(np.abs(quantised).max()) // scale if n else 0
    if whole_max >= 10**7:
        raise ValueError(f'coordinates up to {whole_max} m are out of range for the text writer')
    whole_digits = _digit_table(whole_max + 1, len(str(whole_max)))
    colors = np.asarray(rgb, dtype=np.int64)
    if n and (colors.min() < 0 or colors.max() > 255):
        raise ValueError('colors must be integers in 0..255')
    w = whole_digits.shape[1]
    field_width = 1 + w + 1 + decimals + 1
    whole_rows = np.ascontiguousarray(whole_digits.T)
    fraction_rows = np.ascontiguousarray(fraction_digits.T)
    color_rows = np.ascontiguousarray(_COLOR_DIGITS.T)
    whole_len = (whole_digits != 0).sum(axis=1)
    color_len = (_COLOR_DIGITS != 0).sum(axis=1)
    lengths = np.full(n, 3 * (2 + decimals) + 3 * 1, dtype=np.int64)  # '.', fraction, separators
    # built with one contiguous row per character position, transposed once at the end
    table = np.zeros((3 * field_width + 12, n), dtype=np.uint8)
    for axis in range(3):
        q = np.ascontiguousarray(quantised[:, axis])
        negative = q < 0
        m = np.abs(q)
        whole, fraction = np.divmod(m, scale)
        col = axis * field_width
        table[col] = negative * np.uint8(ord('-'))
        for r in range(w):
            table[col + 1 + r] = whole_rows[r][whole]
        table[col + 1 + w] = ord('.')
        for r in range(decimals):
            table[col + 2 + w + r] = fraction_rows[r][fraction]
        table[col + 2 + w + decimals] = 32
        lengths += negative + whole_len[whole]
    for channel in range(3):
        c = np.ascontiguousarray(colors[:, channel])
        col = 3 * field_width + 4 * channel
        for r in range(3):
            table[col + r] = color_rows[r][c]
        table[col + 3] = 32 if channel < 2 else 10
        lengths += color_len[c]
    table = np.ascontiguousarray(table.T)
    offsets = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(lengths, out=offsets[1:])
    return table[table != 0].tobytes(), offsets
