"""Checks of a loaded model config's values before a tool builds anything from it.

``projects.synthdet.bootstrap.load_config`` runs :func:`check_config_values` after applying
``--cfg-options``, so a config (or an override) that mmengine, mmdet3d or the inference code
would fail on with a traceback later is one line naming the file and the key instead:

- ``model`` is a ``dict(type=...)``;
- no number anywhere is NaN or infinite;
- ``model.voxel_size``, ``inference_window.size``, ``inference_density.floor_area`` and every
  ``PointSample``'s ``num_points`` are positive, ``inference_window.overlap`` is not negative;
- every ``pipeline`` (and ``tta_pipeline``) is a list of ``dict(type=...)`` steps;
- every ``metainfo.classes`` is a list of distinct names (``synthdet.contracts.class_names``).

No ML imports: a config is a nested mapping here.
"""
from __future__ import annotations

import math
from typing import Iterator, Mapping

from synthdet.contracts import SchemaError, class_names

PIPELINE_KEYS = ('pipeline', 'tta_pipeline')
POSITIVE = (('model', 'voxel_size'), ('inference_window', 'size'),
            ('inference_density', 'floor_area'))


class ConfigValueError(ValueError):
    """A config value a tool cannot use; the message names the file and the key."""


def _walk(value: object, where: str) -> Iterator[tuple[str, object]]:
    """Every ``(key path, value)`` of a nested config, the containers included."""
    yield where, value
    if isinstance(value, Mapping):
        for key, item in value.items():
            yield from _walk(item, f'{where}.{key}' if where else str(key))
    elif isinstance(value, (list, tuple)):
        for index, item in enumerate(value):
            yield from _walk(item, f'{where}[{index}]')


def _shown(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 40 else f'{text[:37]}...'


def _check_pipeline(steps: object, where: str, source: str) -> None:
    if not isinstance(steps, (list, tuple)):
        raise ConfigValueError(f'{source}: {where}: expected a list of dict(type=...) steps, '
                               f'got {_shown(steps)}')
    for index, step in enumerate(steps):
        if not isinstance(step, Mapping) or not isinstance(step.get('type'), (str, type)):
            raise ConfigValueError(f'{source}: {where}[{index}]: expected a dict(type=...) '
                                   f'step, got {_shown(step)}')
        if step.get('type') == 'PointSample':
            _check_positive(step.get('num_points'), f'{where}[{index}].num_points', source)


def _check_positive(value: object, where: str, source: str) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
        raise ConfigValueError(f'{source}: {where}: expected a positive number, got '
                               f'{_shown(value)}')


def check_config_values(cfg: Mapping, source: str) -> None:
    """:class:`ConfigValueError` naming ``source`` (the config file) and the key for the
    first value of the rules in the module docstring that ``cfg`` breaks."""
    model = cfg.get('model')
    if not isinstance(model, Mapping) or 'type' not in model:
        raise ConfigValueError(f'{source}: model: expected a dict(type=...) model, got '
                               f'{_shown(model)}')
    for where, value in _walk(dict(cfg.items()), ''):
        if isinstance(value, float) and not math.isfinite(value):
            raise ConfigValueError(f'{source}: {where}: expected a finite number, got {value}')
        key = where.rsplit('.', 1)[-1]
        if key in PIPELINE_KEYS:
            _check_pipeline(value, where, source)
        elif key == 'metainfo' and isinstance(value, Mapping) and 'classes' in value:
            try:
                class_names(value['classes'], source, f'{where}.classes')
            except SchemaError as error:
                raise ConfigValueError(str(error)) from None
    for section, key in POSITIVE:
        part = cfg.get(section)
        if isinstance(part, Mapping) and key in part:
            _check_positive(part[key], f'{section}.{key}', source)
    window = cfg.get('inference_window')
    if isinstance(window, Mapping):
        overlap = window.get('overlap', 0.0)
        if isinstance(overlap, bool) or not isinstance(overlap, (int, float)) or overlap < 0:
            raise ConfigValueError(f'{source}: inference_window.overlap: expected a number >= '
                                   f'0, got {_shown(overlap)}')
