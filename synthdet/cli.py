"""What every command line of the project shares: one error line, checked option values and
checked input files, all before any work (docs/safety.md).

- :class:`OneLineParser` is the ``argparse`` parser of every CLI: a usage error is the single
  line ``PROG: error: MESSAGE`` and exit code 2; the usage block is printed by ``--help`` only.
- :func:`int_in`, :func:`float_in` and :func:`seconds` are ``type=`` functions that accept
  numbers in a range only (NaN, infinities and 300-digit numbers are refused with a short
  message naming the option).
- :func:`check_input_file` says what an input path is when it is not a regular file (a
  folder, a FIFO, a device, a link to one) instead of "not found".

Standard library only: the checks run before a CLI imports numpy, torch or FreeCAD.
"""
from __future__ import annotations

import argparse
import math
import os
import stat
import sys
from typing import Callable, NoReturn

MAX_TIMEOUT = 7 * 24 * 3600.0  # seconds: a week is the longest wait for an outside program
MAX_AREA = 9_999  # the largest S3DIS area number the tools accept (the real S3DIS has 1-6)


class OneLineParser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose errors are one line on stderr (``PROG: error: MESSAGE``)
    and exit code 2; sub-command parsers made by ``add_subparsers`` are of this class too."""

    def error(self, message: str) -> NoReturn:
        """Print ``message`` as one line and exit with code 2 (no usage block)."""
        self.exit(2, f'{self.prog}: error: {" ".join(message.split())}\n')


class InputFileError(ValueError):
    """An input path that is not a readable regular file; the message names it."""


def shown(text: object, limit: int = 24) -> str:
    """``text`` for a message: at most ``limit`` characters (a 300-digit number is cut)."""
    text = str(text)
    return text if len(text) <= limit else f'{text[:limit - 3]}...'


def int_in(low: int, high: int) -> Callable[[str], int]:
    """An argparse ``type``: an integer in ``[low, high]``, with a short message otherwise."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'expected an integer, got {shown(text)}') from None
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(
                f'expected an integer from {low:,} to {high:,}, got {shown(text)}')
        return value

    return parse


def float_in(low: float, high: float, include_low: bool = True) -> Callable[[str], float]:
    """An argparse ``type``: a finite number in ``[low, high]`` (``(low, high]`` without
    ``include_low``), with a short message otherwise."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'expected a number, got {shown(text)}') from None
        if not (math.isfinite(value) and (low <= value if include_low else low < value)
                and value <= high):
            interval = f'{"[" if include_low else "("}{low:g}, {high:g}]'
            raise argparse.ArgumentTypeError(
                f'expected a number in {interval}, got {shown(text)}')
        return value

    return parse


def add_int_option(parser: argparse.ArgumentParser, flag: str, low: int, high: int,
                   default: int, what: str) -> None:
    """Add an integer ``flag`` in [``low``, ``high``]; its help is ``what``, the range and the
    default."""
    parser.add_argument(flag, type=int_in(low, high), default=default,
                        help=f'{what}, {low:,} to {high:,} (default {default})')


def add_score_option(parser: argparse.ArgumentParser, flag: str, default: float,
                     what: str) -> None:
    """Add a score threshold ``flag`` in [0, 1]; its help is ``what``, the interval and the
    default."""
    parser.add_argument(flag, type=float_in(0.0, 1.0), default=default,
                        help=f'{what}, in [0, 1] (default {default:g})')


seconds = float_in(0.0, MAX_TIMEOUT, include_low=False)  # a --timeout: up to a week


def check_input_file(path: str | os.PathLike, what: str) -> None:
    """:class:`InputFileError` unless ``path`` is an existing regular file (after symbolic
    links); the message says what it is instead, e.g. ``scan.ply: is a folder, not a scan
    file`` or ``z.xyz: is a character device (/dev/zero), not a scan file``."""
    name = os.fspath(path)
    try:
        mode = os.stat(name).st_mode
    except FileNotFoundError:
        if os.path.islink(name):
            raise InputFileError(f'{name}: is a broken symbolic link, not a {what}') from None
        raise InputFileError(f'{name}: {what} not found') from None
    except OSError as error:
        raise InputFileError(f'{name}: cannot read ({error.strerror or error})') from None
    if stat.S_ISREG(mode):
        return
    kinds = ((stat.S_ISDIR, 'a folder'), (stat.S_ISFIFO, 'a FIFO (named pipe)'),
             (stat.S_ISCHR, 'a character device'), (stat.S_ISBLK, 'a block device'),
             (stat.S_ISSOCK, 'a socket'))
    kind = next((text for test, text in kinds if test(mode)), 'not a regular file')
    target = os.path.realpath(name)
    link = f' ({target})' if os.path.islink(name) and target != os.path.abspath(name) else ''
    raise InputFileError(f'{name}: is {kind}{link}, not a {what}')


def exit_with_error(prog: str, message: object, code: int = 2) -> NoReturn:
    """Print ``PROG: error: MESSAGE`` (one line) on stderr and exit with ``code``."""
    print(f'{prog}: error: {" ".join(str(message).split())}', file=sys.stderr)
    sys.exit(code)
