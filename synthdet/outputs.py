"""The one way the tools write their outputs: checked before any work, written under a
temporary name of the run beside the target, checked and renamed into place.

- :func:`check_output` (before any work): an output that is a folder (or, for a folder output,
  a file), a device, a FIFO, a socket or the same file as one of the inputs is refused with
  :class:`OutputRefused` (a ``ValueError``: exit 2), one line naming the option and the path.
- :func:`check_output_file`, :func:`check_output_dir` (before any work, by the tools that
  write into a folder they may have to create): :func:`check_output`, then the folder must
  exist (or be creatable) and take a new file: one that cannot (read-only, no permission) is
  :class:`OutputFailed`, exit 1.
- :func:`replaced_file`, :func:`replaced_paths`, :func:`write_bytes`, :func:`write_text`,
  :func:`copy_into_place`: the data goes to ``.<name>.<pid>.<random>.partial<suffix>`` in the
  target's folder, is flushed and synced, its size compared with what was written, then renamed
  over the target. A write that fails (a full disk too) raises :class:`OutputFailed` (an
  ``OSError``: exit 1) naming the target, leaves the previous output as it was and no temporary.
- Temporaries of earlier runs that were killed (their process is gone) are removed from the
  folder before a new one is made there; only names of the pattern above.
- Names are used as the file system gives them: bytes that are not UTF-8 stay bytes in the file
  name (``os.fsencode``); :func:`names_as_given` prints them unchanged in messages.

Standard library only: FreeCAD's own Python loads ``synthdet.contracts``, which writes here.
"""
from __future__ import annotations

import contextlib
import os
import re
import secrets
import shutil
import stat
import sys
import tempfile
from pathlib import Path
from typing import BinaryIO, Iterable, Iterator, Sequence

from synthdet.processes import process_alive

# .<name>.<pid>.<8 hex digits>.partial<suffix>: a run's temporary file or folder; or one of
# the FreeCAD macro's saves beside its document, .<name>.partial-<pid>-<8 hex digits>.FCStd
# (with FreeCAD's backup ...FCStd1 and the macro's rewrites ...FCStd.gui, ...FCStd.shapes)
PARTIAL = re.compile(
    r'\..+\.(?P<pid>\d+)\.[0-9a-f]{8}\.partial(?:\.[^.]*)?'
    r'|\..+\.partial-(?P<macro_pid>\d+)-[0-9a-f]{8}\.FCStd(?:1|\.gui|\.shapes)?', re.DOTALL)
PNG_SIGNATURE = b'\x89PNG\r\n\x1a\n'
PNG_END = b'IEND\xaeB`\x82'  # the last chunk's type and checksum: the file's last 8 bytes
_COPY_CHUNK = 1 << 20
_KINDS = ((stat.S_ISCHR, 'a device'), (stat.S_ISBLK, 'a device'), (stat.S_ISFIFO, 'a FIFO'),
          (stat.S_ISSOCK, 'a socket'))

PathLike = str | bytes | os.PathLike
_CLEANED: set[str] = set()  # the folders this process has cleaned


class OutputRefused(ValueError):
    """An output argument that must not be written (the message names the option and path)."""


class OutputFailed(OSError):
    """An output that cannot be written (a folder this process cannot write in) or could not
    be written whole; the previous file is kept."""


def shown(path: PathLike) -> str:
    """``path`` as text for a message: bytes that are not UTF-8 kept (``surrogateescape``), to be
    printed unchanged by a stream that :func:`names_as_given` set up."""
    return os.fsdecode(path)


def readable(text: str) -> str:
    """``text`` as valid Unicode (for JSON, or a program that needs it): bytes of a file name
    that are not UTF-8 (lone surrogates in Python) become U+FFFD."""
    return text.encode('utf-8', 'surrogateescape').decode('utf-8', 'replace')


def names_as_given() -> None:
    """Print file names to stdout and stderr as the file system gives them: bytes that are not
    UTF-8 come out unchanged instead of failing (stdout) or as ``\\udcXX`` (stderr)."""
    for stream in (sys.stdout, sys.stderr):
        reconfigure = getattr(stream, 'reconfigure', None)
        if reconfigure is not None and (stream.encoding or '').lower().replace('-', '') == 'utf8':
            reconfigure(errors='surrogateescape')


def _kind_problem(mode: int, folder: bool) -> str | None:
    """Why a file of ``mode`` cannot be replaced by an output (a file, or a folder)."""
    for test, kind in _KINDS:
        if test(mode):
            return f'is {kind}, not a {"folder" if folder else "file"}'
    if folder and not stat.S_ISDIR(mode):
        return 'is a file, expected a folder'
    if not folder and stat.S_ISDIR(mode):
        return 'is a folder, expected a file name'
    return None


def check_output(path: PathLike,
                 option: str,
                 inputs: Iterable[PathLike | None] = (),
                 folder: bool = False) -> Path:
    """Refuse (:class:`OutputRefused`) the output ``path`` of ``option`` when it is a folder
    (with ``folder``: anything but a folder), a device, a FIFO, a socket, or the same file as
    one of ``inputs`` (``None`` entries are skipped). Returns ``path`` as a ``Path``."""
    target = Path(os.fsdecode(path))
    try:
        mode = os.stat(target).st_mode
    except FileNotFoundError:  # a new file (or a link to none): nothing to compare
        return target
    except OSError as error:
        raise OutputRefused(f'{option} {shown(target)}: cannot be used '
                            f'({error.strerror or error})') from None
    problem = _kind_problem(mode, folder)
    if problem:
        raise OutputRefused(f'{option} {shown(target)}: {problem}')
    for source in inputs:
        if source is not None and _same_file(target, source):
            raise OutputRefused(f'{option} {shown(target)}: is the input {shown(source)}; '
                                'write the output to another file')
    return target


def _same_file(a: PathLike, b: PathLike) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def _nearest_existing(path: Path) -> Path:
    """``path`` made absolute, or the closest of its parent folders that exists."""
    path = Path(os.path.abspath(path))
    while not os.path.lexists(path) and path != path.parent:
        path = path.parent
    return path


def _check_can_create_in(folder: Path, output: Path) -> None:
    """Create and remove a probe file in ``folder`` (the one check that also holds for root
    and read-only file systems); :class:`OutputFailed` naming ``output`` if it cannot be."""
    try:
        descriptor, name = tempfile.mkstemp(prefix='.write-check-', dir=folder)
    except OSError as error:
        raise OutputFailed(f'{shown(output)}: cannot write in {shown(folder)} '
                           f'({error.strerror or type(error).__name__})') from None
    os.close(descriptor)
    os.unlink(name)


def check_output_dir(path: PathLike,
                     option: str = '--out',
                     inputs: Iterable[PathLike | None] = ()) -> Path:
    """:func:`check_output` for a folder output, then :class:`OutputRefused` unless the folder
    exists or can be created (no file on its way) and :class:`OutputFailed` if this process
    cannot write in it. Nothing is created but a probe file, removed at once."""
    path = check_output(path, option, inputs, folder=True)
    existing = _nearest_existing(path)
    if not existing.is_dir():
        raise OutputRefused(f'{option} {shown(path)}: cannot be created ({shown(existing)} is '
                            'a file)')
    _check_can_create_in(existing, path)
    return path


def check_output_file(path: PathLike,
                      make_parents: bool = False,
                      option: str = '--out',
                      inputs: Iterable[PathLike | None] = ()) -> Path:
    """:func:`check_output` for a file output, then :class:`OutputRefused` unless its folder
    exists (with ``make_parents``: can be created) and :class:`OutputFailed` if this process
    cannot write in it. Nothing is created but a probe file beside it, removed at once."""
    path = check_output(path, option, inputs)
    if make_parents:
        check_output_dir(path.parent, option)
    elif not path.parent.is_dir():
        raise OutputRefused(f'{option} {shown(path)}: the folder {shown(path.parent)} does not '
                            'exist')
    else:
        _check_can_create_in(path.parent, path)
    return path


def temporary_beside(target: Path, folder: bool = False) -> Path:
    """A new name ``.<name>.<pid>.<random>.partial<suffix>`` in ``target``'s folder (no suffix
    for a folder), unique to this process and call."""
    stem, suffix = (target.name, '') if folder else (target.stem, target.suffix)
    return target.with_name(f'.{stem}.{os.getpid()}.{secrets.token_hex(4)}.partial{suffix}')


def remove_stale_temporaries(folder: PathLike) -> list[Path]:
    """Remove the temporaries (:data:`PARTIAL` names) that runs no longer alive left in
    ``folder``; those of live runs and every other name stay. Returns the removed paths."""
    folder = Path(os.fsdecode(folder))
    key = os.path.realpath(folder)
    if key in _CLEANED:  # once a folder and process: a tool writing many files there
        return []
    _CLEANED.add(key)
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return []
    removed = []
    for entry in entries:
        match = PARTIAL.fullmatch(entry.name)
        if match is None or process_alive(int(match['pid'] or match['macro_pid'])):
            continue
        with contextlib.suppress(OSError):  # removed by another run meanwhile
            if entry.is_dir(follow_symlinks=False):
                shutil.rmtree(entry.path)
            else:
                os.unlink(entry.path)
            removed.append(Path(entry.path))
    return removed


def _failed(target: Path, error: OSError) -> OutputFailed:
    reason = error.strerror or str(error)
    return OutputFailed(f'{shown(target)}: cannot write: {reason}; the previous file is kept, '
                        'nothing half-written is left')


def _remove(path: Path) -> None:
    """Remove ``path`` if it exists (on a read-only file system unlinking a missing name fails
    with EROFS, not ENOENT)."""
    if not os.path.lexists(path):
        return
    with contextlib.suppress(FileNotFoundError):
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        else:
            path.unlink()


def _sync_file(path: Path) -> None:
    """Write ``path``'s data to the disk; a full disk may only show here."""
    descriptor = os.open(path, os.O_RDONLY)
    try:
        os.fsync(descriptor)
    finally:
        os.close(descriptor)


def _sync_folder(folder: Path) -> None:
    with contextlib.suppress(OSError):  # not every file system syncs folders
        _sync_file(folder)


def _check_written(temporary: Path, target: Path, folder: bool) -> None:
    """Raise :class:`OutputFailed` unless ``temporary`` is a non-empty file (or a folder) that
    reached the disk."""
    if folder:
        if not temporary.is_dir():
            raise OutputFailed(f'{shown(target)}: the output was not written')
        return
    if not temporary.is_file() or temporary.stat().st_size == 0:
        raise OutputFailed(f'{shown(target)}: the output was not written (empty or missing)')
    _sync_file(temporary)


def _rename_into_place(temporary: Path, target: Path, folder: bool) -> None:
    """Rename ``temporary`` over ``target`` (a folder: the previous one moved aside first)."""
    if os.path.lexists(target):
        problem = _kind_problem(os.stat(target).st_mode, folder) \
            if os.path.exists(target) else None
        if problem:
            raise OutputRefused(f'{shown(target)}: {problem}')
    if folder and os.path.lexists(target):
        old = temporary.with_name(f'{temporary.name}.old')  # a PARTIAL name too
        os.replace(target, old)
        os.replace(temporary, target)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.replace(temporary, target)


@contextlib.contextmanager
def replaced_paths(targets: Sequence[PathLike], folders: bool = False) -> Iterator[list[Path]]:
    """Temporary paths beside ``targets`` (folders with ``folders``, created empty) for the
    block to write; when it succeeds each is checked (non-empty, synced) and renamed over its
    target, all after the last one is complete. A failure raises :class:`OutputFailed` for
    ``OSError``s; whatever happens no temporary is left and failed targets stay as they were.
    Stale temporaries of killed runs in the targets' folders are removed first."""
    targets = [Path(os.fsdecode(target)) for target in targets]
    temporaries: list[Path] = []
    current = targets[0] if targets else Path('.')
    try:
        for target in targets:
            current = target
            target.parent.mkdir(parents=True, exist_ok=True)
            remove_stale_temporaries(target.parent)
            temporaries.append(temporary_beside(target, folders))
            if folders:
                temporaries[-1].mkdir()
        yield temporaries
        for temporary, target in zip(temporaries, targets):
            current = target
            _check_written(temporary, target, folders)
        for temporary, target in zip(temporaries, targets):
            current = target
            _rename_into_place(temporary, target, folders)
            _sync_folder(target.parent)
    except OutputFailed:
        raise
    except OSError as error:
        raise _failed(current, error) from None
    finally:
        for temporary in temporaries:
            _remove(temporary)


@contextlib.contextmanager
def replaced_file(target: PathLike) -> Iterator[BinaryIO]:
    """A binary stream on a temporary file beside ``target``; when the block succeeds the data
    is flushed, synced, its size compared with the bytes written, and the file renamed over
    ``target`` (see :func:`replaced_paths`)."""
    with replaced_paths([target]) as (temporary, ):
        with open(temporary, 'wb') as stream:
            yield stream
            stream.flush()
            os.fsync(stream.fileno())
            _check_size(stream, target)


def _check_size(stream: BinaryIO, target: PathLike) -> None:
    """Raise :class:`OutputFailed` unless the file holds every byte written to ``stream``."""
    written, stored = stream.tell(), os.fstat(stream.fileno()).st_size
    if stored != written:
        raise OutputFailed(f'{shown(target)}: only {stored} of {written} bytes were stored; '
                           'the previous file is kept')


def write_bytes(target: PathLike, data: bytes) -> None:
    """Write ``data`` to ``target`` through a checked temporary file (:func:`replaced_file`)."""
    with replaced_file(target) as stream:
        stream.write(data)


def write_text(target: PathLike, text: str) -> None:
    """Write ``text`` as UTF-8 to ``target`` (:func:`write_bytes`); text that is not Unicode
    fails before any file exists."""
    write_bytes(target, text.encode('utf-8'))


def check_png(data: bytes, source: PathLike) -> None:
    """Raise :class:`OutputFailed` unless ``data`` is a whole PNG (signature to end chunk)."""
    if not (data.startswith(PNG_SIGNATURE) and data.endswith(PNG_END)):
        raise OutputFailed(f'{shown(source)}: the picture is incomplete ({len(data)} bytes, no '
                           'PNG end); nothing was written')


def copy_into_place(pairs: Sequence[tuple[PathLike, PathLike]]) -> None:
    """Copy each finished file ``source`` of ``(source, target)`` (e.g. one FreeCAD wrote in a
    work folder) to a temporary file beside ``target``, then rename them all into place
    (:func:`replaced_paths`): the targets are replaced together or not at all."""
    with replaced_paths([target for _, target in pairs]) as temporaries:
        for (source, target), temporary in zip(pairs, temporaries):
            try:
                with open(source, 'rb') as reader, open(temporary, 'wb') as stream:
                    shutil.copyfileobj(reader, stream, _COPY_CHUNK)
                    stream.flush()
                    os.fsync(stream.fileno())
                    _check_size(stream, target)
            except OSError as error:
                raise _failed(Path(os.fsdecode(target)), error) from None
