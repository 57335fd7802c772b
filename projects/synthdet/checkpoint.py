"""Checkpoints that cannot run code: weights-only loads, inference checkpoints, trusted resume.

A checkpoint is a pickle, and a pickle can run any code when it is loaded. Every load here uses
``torch.load(weights_only=True)``: tensors, plain containers and numbers, plus the few data-only
types an mmengine training checkpoint holds (numpy arrays and scalars, mmengine's
``HistoryBuffer`` and a ``getattr`` limited to its four statistics methods), listed in
:data:`TRAINING_CHECKPOINT_TYPES`. Anything else (such as a
``__reduce__`` that calls a function) is refused with :class:`CheckpointError`, before it runs.

An inference checkpoint (:func:`inference_checkpoint`, written at the end of training and by
``tools/publish_model.py``) keeps only ``state_dict`` and plain-typed ``meta``, like mmdet's
``publish_model``: it loads with ``weights_only=True`` and no extra type at all.

Full unpickling exists for one case only: ``tools/train.py --resume CKPT --trust-checkpoint``,
for a checkpoint inside the run's own work directory, through the ``trusted://`` prefix that
:func:`trusted_resume_path` gives that single path.
"""
from __future__ import annotations
import hashlib
import io
import os
import pickle
import re
from pathlib import Path

import numpy as np
import torch

from synthdet.outputs import write_bytes

TRUSTED_PREFIX = 'trusted://'
_HISTORY_BUFFER_STATISTICS = ('min', 'max', 'current', 'mean')
_DROP = object()  # marks values an inference checkpoint leaves out


class CheckpointError(ValueError):
    """A checkpoint that cannot be loaded safely or is not a checkpoint; names the file."""


def _history_buffer_statistic(owner: object, name: str) -> object:
    """The ``getattr`` a training checkpoint may call: HistoryBuffer's statistics methods only.

    mmengine pickles ``HistoryBuffer._statistics_methods`` as ``getattr(HistoryBuffer, 'min')``
    and so on; a general ``getattr`` would reach any attribute, so it is never allowed.
    """
    from mmengine.logging.history_buffer import HistoryBuffer
    if owner is not HistoryBuffer or name not in _HISTORY_BUFFER_STATISTICS:
        raise pickle.UnpicklingError(f'getattr({owner!r}, {name!r}) is not allowed')
    return getattr(owner, name)


def _training_checkpoint_types() -> list:
    from mmengine.logging.history_buffer import HistoryBuffer
    numpy_types = [
        np.ndarray, np.dtype, np.core.multiarray._reconstruct, np.core.multiarray.scalar
    ]
    dtype_classes = [
        type(np.dtype(name))
        for name in ('f2', 'f4', 'f8', 'i1', 'i2', 'i4', 'i8', 'u1', 'u2', 'u4', 'u8', '?')
    ]
    getattr_names = [(_history_buffer_statistic, f'{module}.getattr')
                     for module in ('builtins', '__builtin__')]
    return [HistoryBuffer, *numpy_types, *dtype_classes, *getattr_names]


TRAINING_CHECKPOINT_TYPES = _training_checkpoint_types()


def load_checkpoint_file(path: str | os.PathLike,
                         hint: str = 'load only checkpoints from a source you trust') -> dict:
    """Load a checkpoint with ``weights_only=True``; returns its dictionary.

    Raises :class:`CheckpointError` naming the file if it is missing, not a PyTorch checkpoint
    (a text file, a truncated or damaged one), has no ``state_dict``, or holds a type outside
    :data:`TRAINING_CHECKPOINT_TYPES` (the message names what was refused, then ``hint``).
    """
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f'{path}: checkpoint file not found')
    try:
        with torch.serialization.safe_globals(TRAINING_CHECKPOINT_TYPES):
            checkpoint = torch.load(path, map_location='cpu', weights_only=True)
    except pickle.UnpicklingError as error:
        if refused_item(error) is None:
            raise not_a_checkpoint(path, error) from None
        raise refused(path, error, hint) from None
    except MemoryError:
        raise CheckpointError(f'{path}: not a PyTorch checkpoint (too large to load)') from None
    except Exception as error:  # a damaged pickle fails with any error (IndexError, KeyError)
        raise not_a_checkpoint(path, error) from None
    if not isinstance(checkpoint, dict) or not isinstance(checkpoint.get('state_dict'), dict):
        raise CheckpointError(f'{path}: not an mmengine checkpoint (no "state_dict")')
    return checkpoint


def not_a_checkpoint(path: str | os.PathLike, error: Exception) -> CheckpointError:
    """The one-line error for a file ``torch.load`` cannot read (text, truncated, damaged)."""
    with open(path, 'rb') as stream:
        zipped = stream.read(4) == b'PK\x03\x04'  # torch.save writes a zip archive
    if not zipped:  # a text file, say: the unpickler's error (a pop, a key) tells nothing
        return CheckpointError(f'{path}: not a PyTorch checkpoint (torch.load cannot read it)')
    return CheckpointError(
        f'{path}: a truncated or damaged PyTorch checkpoint ({_first_sentence(error)})')


def _first_sentence(error: BaseException, limit: int = 80) -> str:
    """The first sentence of an error's message, at most ``limit`` characters."""
    text = str(error).strip().split('\n')[0].split('. ')[0].strip() or type(error).__name__
    return text if len(text) <= limit else text[:limit - 3] + '...'


def refused_item(error: pickle.UnpicklingError) -> str | None:
    """What the weights-only unpickler refused (a global's dotted name, an object's type);
    None when the error is not a refusal but a damaged pickle."""
    text = str(error)
    for pattern in (r'GLOBAL (\S+)', r'but got (<class \'[^\']+\'>|\S+)',
                    r'(getattr\(.{0,80}?\)) is not allowed'):
        match = re.search(pattern, text)
        if match:
            item = match.group(1).rstrip('.')
            return item if len(item) <= 100 else item[:97] + '...'
    return None


def refused(path: str | os.PathLike, error: pickle.UnpicklingError, hint: str) -> CheckpointError:
    """The one-line error for a checkpoint the weights-only unpickler refused: what it holds
    besides weights and data, and that the file was not loaded."""
    item = refused_item(error) or _first_sentence(error)
    return CheckpointError(f'{path}: refused: the checkpoint holds {item}, which is not weights '
                           f'or data (unpickling it could run code); the file was not loaded; '
                           f'{hint} (README "Safety")')


def check_resumable(path: str | os.PathLike) -> None:
    """Check, weights-only, that ``path`` is a training checkpoint mmengine can resume from
    (``meta.epoch``, ``meta.iter`` and ``message_hub``); :class:`CheckpointError` otherwise."""
    checkpoint = load_checkpoint_file(
        path, hint='if it is your own, resume it with --trust-checkpoint')
    meta = checkpoint.get('meta')
    if (not isinstance(meta, dict) or not isinstance(checkpoint.get('message_hub'), dict)
            or not all(isinstance(meta.get(key), int) for key in ('epoch', 'iter'))):
        raise CheckpointError(
            f'{path}: cannot resume: no training state (meta.epoch, meta.iter, message_hub), as '
            'in an inference checkpoint; resume from an epoch_N.pth, or start from its weights '
            'with --cfg-options load_from=CKPT')


def load_model_weights(model: torch.nn.Module, path: str | os.PathLike) -> dict:
    """Load a checkpoint's weights into ``model`` (every key must match); returns its ``meta``."""
    return load_state_into(model, load_checkpoint_file(path), path)


def load_state_into(model: torch.nn.Module, checkpoint: dict, path: str | os.PathLike) -> dict:
    """Load the ``state_dict`` of a checkpoint loaded by :func:`load_checkpoint_file` from
    ``path`` into ``model`` (every key must match); returns its ``meta``."""
    state_dict = {
        key.removeprefix('module.'): value
        for key, value in checkpoint['state_dict'].items()
    }
    try:
        model.load_state_dict(state_dict, strict=True)
    except RuntimeError as error:
        first = str(error).splitlines()[1].strip() if '\n' in str(error) else str(error)
        raise CheckpointError(
            f'{path}: weights do not fit the config\'s model ({_shortened(first)})') from None
    meta = checkpoint.get('meta')
    return meta if isinstance(meta, dict) else {}


def _shortened(text: str, limit: int = 200) -> str:
    return text if len(text) <= limit else text[:limit - 3] + '...'


def _plain(value: object) -> object:
    """``value`` as str/int/float/bool/None, lists, tuples and str-keyed dicts; else ``_DROP``.

    numpy scalars become Python numbers; other types (and containers holding them) are dropped.
    """
    if isinstance(value, np.generic):
        value = value.item()
    if value is None:
        return value
    for base in (bool, int, float, str):  # subclasses (an IntEnum, say) become the base type
        if isinstance(value, base):
            return base(value)
    if isinstance(value, (list, tuple)):
        items = [_plain(item) for item in value]
        return _DROP if any(item is _DROP for item in items) else type(value)(items)
    if isinstance(value, dict) and all(isinstance(key, str) for key in value):
        kept = {key: _plain(item) for key, item in value.items()}
        return {key: item for key, item in kept.items() if item is not _DROP}
    return _DROP


def inference_checkpoint(checkpoint: dict) -> dict:
    """``state_dict`` and the plain-typed part of ``meta`` of a training checkpoint."""
    meta = _plain(checkpoint.get('meta') or {})
    return {'meta': meta if isinstance(meta, dict) else {}, 'state_dict': checkpoint['state_dict']}


def save_inference_checkpoint(checkpoint: dict,
                              out: str | os.PathLike,
                              digest_suffix: bool = False) -> Path:
    """Write :func:`inference_checkpoint` of ``checkpoint`` to ``out`` atomically; returns it.

    With ``digest_suffix`` the file is named ``<out stem>-<first 8 hex digits of its
    SHA-256>.pth`` (mmdet's published-model name) and ``out`` itself is never written. The
    checkpoint is serialised in memory, reloaded with plain ``weights_only=True`` and written
    through a checked temporary file of this run, renamed into place (``synthdet.outputs``).
    """
    out = Path(out)
    buffer = io.BytesIO()
    torch.save(inference_checkpoint(checkpoint), buffer)
    data = buffer.getvalue()
    torch.load(io.BytesIO(data), map_location='cpu', weights_only=True)
    if digest_suffix:
        out = out.with_name(f'{out.stem}-{hashlib.sha256(data).hexdigest()[:8]}.pth')
    write_bytes(out, data)
    return out


def trusted_resume_path(checkpoint: str | os.PathLike, work_dir: str | os.PathLike) -> str:
    """``trusted://<checkpoint>`` after checking that it lies inside ``work_dir``.

    Registers the ``trusted://`` loader with mmengine: it unpickles fully, and only the path
    returned here carries the prefix. Raises :class:`CheckpointError` for a checkpoint outside
    the work directory.
    """
    checkpoint, work_dir = Path(checkpoint).resolve(), Path(work_dir).resolve()
    if not checkpoint.is_relative_to(work_dir):
        raise CheckpointError(f'{checkpoint}: --trust-checkpoint resumes only from a checkpoint '
                              f'inside the work directory {work_dir}')
    if not checkpoint.is_file():
        raise CheckpointError(f'{checkpoint}: checkpoint file not found')
    from mmengine.runner.checkpoint import CheckpointLoader
    CheckpointLoader.register_scheme(TRUSTED_PREFIX, _load_trusted, force=True)
    return TRUSTED_PREFIX + str(checkpoint)


def _load_trusted(filename: str, map_location: object = None) -> dict:
    """Full unpickling of the one checkpoint the user vouched for (``trusted://`` paths)."""
    return torch.load(
        filename[len(TRUSTED_PREFIX):], map_location=map_location, weights_only=False)
