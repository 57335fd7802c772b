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


def areas_once(area_dataset: Mapping[str, Any], pipeline: Sequence[Mapping[str, Any]],
               areas: Iterable[int], metainfo: Mapping[str, Any]) -> dict:
    """Override of the ``train_dataloader`` of ``_base_/s3dis-synthdet.py``: one epoch lists
    each of ``areas`` once (``times=1``; an area listed twice is read twice), every dataset
    with ``pipeline`` and ``metainfo``."""
    datasets = area_datasets(dict(area_dataset, pipeline=pipeline), areas, metainfo)
    return dict(dataset=dict(times=1, dataset=dict(datasets=datasets)))


def area_loaders(area_dataset: Mapping[str, Any], train_area: Iterable[int], test_area: int,
                 metainfo: Mapping[str, Any]) -> tuple[dict, dict]:
    """Overrides of the ``train_dataloader`` and ``val_dataloader`` (also the test loader) of
    ``_base_/s3dis-synthdet.py``: train on ``train_area`` (the datasets of its ConcatDataset),
    validate and test on ``test_area``, all with ``metainfo``."""
    train = dict(
        dataset=dict(dataset=dict(datasets=area_datasets(area_dataset, train_area, metainfo))))
    test = dict(dataset=dict(ann_file=area_info_file(test_area), metainfo=metainfo))
    return train, test


def _point_sample_index(pipeline: Sequence[Mapping[str, Any]]) -> int:
    """Index of the first ``PointSample`` step; ``ValueError`` if there is none."""
    types = [step['type'] for step in pipeline]
    if 'PointSample' not in types:
        raise ValueError(f'the pipeline has no PointSample step: {types}')
    return types.index('PointSample')


def with_num_points(pipeline: Sequence[Mapping[str, Any]], num_points: int) -> list[dict]:
    """A copy of ``pipeline`` whose ``PointSample`` steps sample ``num_points`` points.

    Raises ``ValueError`` if the pipeline has no ``PointSample`` step.
    """
    _point_sample_index(pipeline)
    return [
        dict(step, num_points=num_points) if step['type'] == 'PointSample' else dict(step)
        for step in pipeline
    ]


def with_structure_thinning(pipeline: Sequence[Mapping[str, Any]],
                            thinning: Mapping[str, Any]) -> list[dict]:
    """A copy of ``pipeline`` with the ``thinning`` step (a ``ThinRoomStructure`` dict) right
    before its ``PointSample``, so that the sampled points fall more often on objects.

    Raises ``ValueError`` if the pipeline has no ``PointSample`` or already thins.
    """
    index = _point_sample_index(pipeline)
    if any(step['type'] == 'ThinRoomStructure' for step in pipeline):
        raise ValueError(f'the pipeline already thins: {[step["type"] for step in pipeline]}')
    steps = [dict(step) for step in pipeline]
    return steps[:index] + [dict(thinning)] + steps[index:]


def with_voxel_grid_sample(pipeline: Sequence[Mapping[str, Any]],
                           voxel_size: float) -> list[dict]:
    """A copy of ``pipeline`` with a ``VoxelGridSample`` of ``voxel_size`` right before its
    structure thinning (or, without one, its ``PointSample``): one point per occupied cube, so
    that the thinning and the sampling draw evenly over the scanned surfaces.

    Raises ``ValueError`` if the pipeline has no ``PointSample`` or already has the grid.
    """
    index = _point_sample_index(pipeline)
    types = [step['type'] for step in pipeline]
    if 'VoxelGridSample' in types:
        raise ValueError(f'the pipeline already has a voxel grid: {types}')
    if 'ThinRoomStructure' in types:
        index = min(index, types.index('ThinRoomStructure'))
    steps = [dict(step) for step in pipeline]
    return steps[:index] + [dict(type='VoxelGridSample', voxel_size=voxel_size)] + steps[index:]


PRE_SAMPLING_STEPS = ('VoxelGridSample', 'ThinRoomStructure')


def without_pre_sampling(pipeline: Sequence[Mapping[str, Any]]) -> list[dict]:
    """A copy of ``pipeline`` without the steps that prepare its ``PointSample`` (the voxel
    grid and the structure thinning)."""
    return [dict(step) for step in pipeline if step['type'] not in PRE_SAMPLING_STEPS]


def without_robustness(pipeline: Sequence[Mapping[str, Any]],
                       augmentations: Sequence[Mapping[str, Any]]) -> list[dict]:
    """A copy of ``pipeline`` without the steps of ``augmentations`` (the inverse of
    ``with_robustness``, for a config whose base trains with them)."""
    types = {step['type'] for step in augmentations}
    return [dict(step) for step in pipeline if step['type'] not in types]


def with_robustness(pipeline: Sequence[Mapping[str, Any]],
                    augmentations: Sequence[Mapping[str, Any]]) -> list[dict]:
    """A copy of the train ``pipeline`` with ``augmentations`` (``robust_augmentations`` of
    ``_base_/s3dis-synthdet.py``) inserted right after its ``PointSample`` step.

    There the point dropout and thinning change what the model sees (before it, sampling would
    refill the count), they work on the sampled points only, and the color steps act on
    0..255 colors before ``NormalizePointsColor``. Raises ``ValueError`` if the pipeline has no
    ``PointSample``, normalises colors before it, or already holds one of the augmentations.
    """
    index = _point_sample_index(pipeline)
    types = [step['type'] for step in pipeline]
    if 'NormalizePointsColor' in types[:index]:
        raise ValueError(f'the pipeline normalises colors before PointSample: {types}')
    repeated = sorted({step['type'] for step in augmentations} & set(types))
    if repeated:
        raise ValueError(f'the pipeline already has {repeated}: {types}')
    steps = [dict(step) for step in pipeline]
    return steps[:index + 1] + [dict(step) for step in augmentations] + steps[index + 1:]


BEV_FLIPS = tuple(
    dict(
        type='RandomFlip3D',
        sync_2d=False,
        flip_ratio_bev_horizontal=horizontal,
        flip_ratio_bev_vertical=vertical) for horizontal in (0.0, 1.0) for vertical in (0.0, 1.0))


def with_test_time_augmentation(pipeline: Sequence[Mapping[str, Any]],
                                draws: int = 2) -> list[dict]:
    """The ``tta_pipeline`` of a test ``pipeline``: after its first step (the loading), every
    scene goes through the rest in ``4 * draws`` versions, the four flips in x and y (identity
    included) times ``draws`` random point samples each (mmcv's ``TestTimeAug``), for the
    ``SynthdetTTAModel`` to fuse.

    Raises ``ValueError`` if the pipeline has no ``PointSample`` or ``draws`` is below 1.
    """
    index = _point_sample_index(pipeline)
    if draws < 1:
        raise ValueError(f'draws must be at least 1, got {draws}')
    load, *steps = [dict(step) for step in pipeline]
    transforms = [[dict(flip) for flip in BEV_FLIPS]]
    for position, step in enumerate(steps, start=1):
        transforms.append([dict(step) for _ in range(draws)] if position == index else [step])
    return [load, dict(type='TestTimeAug', transforms=transforms)]
