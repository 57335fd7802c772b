"""Helpers that the configs in ``configs/tr3d/`` call to derive from ``_base_`` (no ML imports).

mmengine evaluates a base config before the configs that inherit from it and drops functions
from it, so a derived config cannot ask its base to build one dataset per area of its own list.
The configs import these helpers instead (below their ``_base_`` line: an import above it makes
mmengine treat the file as a new-style config)::

    from projects.synthdet.config_helpers import area_loaders, with_num_points
"""
from typing import Any, Iterable, Mapping, Sequence


def area_info_file(area: int) -> str:
    """The info pickle of an area, as written by ``tools/create_data.py``."""
    return f's3dis_infos_Area_{area}.pkl'


def area_datasets(area_dataset: Mapping[str, Any], areas: Iterable[int],
                  metainfo: Mapping[str, Any]) -> list[dict]:
    """One copy of ``area_dataset`` per area, reading that area's info pickle with ``metainfo``
    (the classes), for the ``datasets`` of a ``ConcatDataset``."""
    return [dict(area_dataset, ann_file=area_info_file(area), metainfo=metainfo) for area in areas]


def area_loaders(area_dataset: Mapping[str, Any], train_area: Iterable[int], test_area: int,
                 metainfo: Mapping[str, Any]) -> tuple[dict, dict]:
    """Overrides of the ``train_dataloader`` and ``val_dataloader`` (also the test loader) of
    ``_base_/s3dis-synthdet.py``: train on ``train_area`` (the datasets of its ConcatDataset),
    validate and test on ``test_area``, all with ``metainfo``."""
    train = dict(
        dataset=dict(dataset=dict(datasets=area_datasets(area_dataset, train_area, metainfo))))
    test = dict(dataset=dict(ann_file=area_info_file(test_area), metainfo=metainfo))
    return train, test


def with_num_points(pipeline: Sequence[Mapping[str, Any]], num_points: int) -> list[dict]:
    """A copy of ``pipeline`` whose ``PointSample`` steps sample ``num_points`` points.

    Raises ``ValueError`` if the pipeline has no ``PointSample`` step.
    """
    if not any(step['type'] == 'PointSample' for step in pipeline):
        raise ValueError(f'the pipeline has no PointSample step: {[s["type"] for s in pipeline]}')
    return [
        dict(step, num_points=num_points) if step['type'] == 'PointSample' else dict(step)
        for step in pipeline
    ]
