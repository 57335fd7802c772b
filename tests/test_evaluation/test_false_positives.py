"""The false-positive causes of ``tools/test.py --false-positives`` on a hand-built room.

The room is written in S3DIS format (a wall, a table, a 3D printer and a crate as clutter, with
a generator ``meta.json`` naming the crate's asset) and converted by the real converter; the
predictions are boxes placed on purpose on each kind of mistake. The AP is checked against
mmdet3d's own IndoorMetric on the same predictions.
"""
import json
from pathlib import Path

import numpy as np
import pytest
import torch
from mmdet3d.structures import DepthInstance3DBoxes

from projects.synthdet.datasets.s3dis_converter import convert_s3dis
from projects.synthdet.evaluation.false_positives import (MATCHED, ScanFiles,
                                                          SynthdetFalsePositives,
                                                          false_positives_document,
                                                          format_false_positives, match_scan)
from projects.synthdet.evaluation.indoor_metric import SynthdetIndoorMetric
from synthdet.classes import DETECTION_CLASSES
from synthdet.contracts import ROOM_FORMAT
from synthdet.info_files import InfoFileError, load_info_pickle
from tests.s3dis_fixtures import S3DIS_DIR

CLASSES = DETECTION_CLASSES  # the labels of the info pickle
TABLE, PRINTER = CLASSES.index('table'), CLASSES.index('3dprinter')
# annotation: (min corner, max corner) of a solid box sampled by its surface
ROOM = {
    'wall_1': ((0.0, 0.0, 0.0), (6.0, 0.02, 3.0)),
    'table_1': ((1.0, 1.0, 0.0), (2.6, 1.8, 0.75)),
    '3dprinter_1': ((3.5, 2.0, 0.0), (4.0, 2.5, 0.6)),
    'clutter_1': ((1.2, 1.1, 0.75), (1.7, 1.6, 1.25)),  # a printer-sized crate on the table
}


def _surface(rng: np.random.Generator, lo: tuple, hi: tuple, n: int) -> np.ndarray:
    points = rng.uniform(lo, hi, (n, 3))
    axis = rng.integers(0, 3, n)
    points[np.arange(n),
           axis] = np.where(rng.random(n) < 0.5,
                            np.asarray(lo)[axis],
                            np.asarray(hi)[axis])
    return points


@pytest.fixture(scope='module')
def room(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """The room converted into ``data/``, the raw rooms inside it as create_data lays them."""
    data = tmp_path_factory.mktemp('false_positives') / 'data'
    room_dir = data / S3DIS_DIR / 'Area_9' / 'factory_1'
    (room_dir / 'Annotations').mkdir(parents=True)
    rng = np.random.default_rng(0)
    chunks = []
    for name, (lo, hi) in ROOM.items():
        points = np.column_stack([_surface(rng, lo, hi, 1500), np.full((1500, 3), 128.0)])
        np.savetxt(room_dir / 'Annotations' / f'{name}.txt', points, fmt='%.4f')
        chunks.append(points)
    np.savetxt(room_dir / 'factory_1.txt', np.concatenate(chunks), fmt='%.4f')
    objects = [{
        'instance': name,
        'class': name.rsplit('_', 1)[0],
        'asset': asset,
        'box': {
            'center': list((np.add(lo, hi) / 2)),
            'size': list(np.subtract(hi, lo))
        }
    } for (name, (lo, hi)), asset in zip(
        list(ROOM.items())[1:], ('table/legs', '3dprinter/enclosed', 'clutter/crate'))]
    meta = {
        'format': ROOM_FORMAT,
        'objects': objects,
        'room': {
            'polygon': [[0, 0], [0, 4], [6, 4], [6, 0]],
            'height': 3.0
        }
    }
    (room_dir / 'meta.json').write_text(json.dumps(meta))
    convert_s3dis(data, data, areas=[9])
    info = load_info_pickle(data / 's3dis_infos_Area_9.pkl')['data_list'][0]
    instances = info['instances']
    truth = DepthInstance3DBoxes(
        torch.tensor([[*i['bbox_3d'], 0.0] for i in instances]), origin=(0.5, 0.5, 0.5))
    return dict(
        lidar_path=str(data / 'points' / info['lidar_points']['lidar_path']),
        truth=truth,
        labels=np.array([i['bbox_label_3d'] for i in instances]),
        data=data,
        room_dir=room_dir)


def _shifted(box_min: tuple, box_max: tuple, shift: np.ndarray) -> list[float]:
    """A box (centre, size, yaw 0) of the raw frame, in the converted (shifted) frame."""
    lo, hi = np.asarray(box_min) - shift, np.asarray(box_max) - shift
    return [*((lo + hi) / 2), *(hi - lo), 0.0]


@pytest.fixture(scope='module')
def predictions(room: dict) -> tuple:
    """One printer prediction per kind of outcome, highest score first, and the outcomes."""
    shift = np.min([lo for lo, _ in ROOM.values()], axis=0)
    printer, table, crate = ROOM['3dprinter_1'], ROOM['table_1'], ROOM['clutter_1']
    boxes = [
        (_shifted(*printer, shift), 0.9, MATCHED),
        (_shifted(*printer, shift), 0.8, 'duplicate'),
        (_shifted(*crate, shift), 0.7, 'clutter/crate'),
        (_shifted(*table, shift), 0.6, f'as {TABLE}'),
        (_shifted((3.85, 2.0, 0.0), (4.35, 2.5, 0.6), shift), 0.5, 'loose'),  # IoU 0.18
        (_shifted((4.5, 3.0, 1.5), (5.0, 3.5, 2.0), shift), 0.4, 'empty'),  # in the air
        (_shifted((0.5, 0.0, 0.5), (1.0, 0.4, 1.0), shift), 0.3, 'wall'),
        (_shifted(*crate, shift), 0.05, 'score < 0.1'),
    ]
    tensor = torch.tensor([box for box, _, _ in boxes], dtype=torch.float32)
    return (DepthInstance3DBoxes(tensor, origin=(0.5, 0.5, 0.5)),
            np.array([score for _, score, _ in boxes]), [outcome for _, _, outcome in boxes])


def test_each_false_positive_gets_its_cause(room: dict, predictions: tuple) -> None:
    boxes, scores, expected = predictions
    labels = np.full(len(scores), PRINTER)
    scan = ScanFiles(room['lidar_path'])
    assert scan.names == ['3dprinter/enclosed', 'clutter/crate', 'table/legs', 'wall']
    # the predictions shuffled: the outcome depends on the scores, not on the order
    order = np.random.default_rng(1).permutation(len(scores))
    outcomes = match_scan(room['truth'], room['labels'], boxes[order], labels, scores[order], 0.25,
                          0.1, scan)
    assert [outcomes[list(order).index(k)] for k in range(len(scores))] == expected
    # at IoU 0.5 the loose box stays loose; the first match is exact
    assert match_scan(room['truth'], room['labels'], boxes, labels, scores, 0.5, 0.1,
                      scan)[:5] == expected[:5]


def test_the_metric_reproduces_indoor_metric_and_ranks_the_causes(room: dict,
                                                                  predictions: tuple) -> None:
    boxes, scores, _ = predictions
    # and an exact table prediction, so that two classes have true boxes and predictions
    table = int(np.flatnonzero(room['labels'] == TABLE)[0])
    boxes = DepthInstance3DBoxes(torch.cat([boxes.tensor, room['truth'].tensor[[table]]]))
    labels = torch.tensor([PRINTER] * len(scores) + [TABLE])
    scores = torch.tensor([*scores, 0.95], dtype=torch.float32)
    sample = {
        'lidar_path': room['lidar_path'],
        'eval_ann_info': {
            'gt_bboxes_3d': room['truth'],
            'gt_labels_3d': room['labels']
        },
        'pred_instances_3d': {
            'bboxes_3d': boxes,
            'labels_3d': labels,
            'scores_3d': scores
        },
    }
    metric = SynthdetFalsePositives()
    metric.dataset_meta = {'classes': CLASSES}
    metric.process({}, [sample])
    results = metric.compute_metrics(metric.results)
    reference = SynthdetIndoorMetric()
    reference.dataset_meta = {'classes': CLASSES}
    reference.process({}, [sample])
    expected = reference.compute_metrics(reference.results)
    for name in ('table', '3dprinter'):
        for thr in ('0.25', '0.50'):
            assert results[f'{name}|{thr}|AP'] == pytest.approx(expected[f'{name}_AP_{thr}'])
    # the printer: 1 true box, matched first; then 6 false positives before the last one
    assert results['3dprinter|0.25|AP'] == pytest.approx(1.0)
    document = false_positives_document({
        f'fp/{k}': v
        for k, v in results.items()
    }, list(CLASSES), 'c.py', 'w.pth', 'area 9')
    assert list(document['rows']) == ['table', '3dprinter']  # classes with true boxes
    causes = document['rows']['3dprinter']['0.25']['causes']
    assert set(causes) == {
        'duplicate', 'clutter/crate', 'as table', 'loose', 'empty', 'wall', 'score < 0.1'
    }
    assert all(cause['count'] == 1 for cause in causes.values())
    # leaving out the false positives of a cause never lowers the AP
    printer = document['rows']['3dprinter']['0.50']
    assert all(c['ap_without'] >= printer['AP'] - 1e-9 for c in printer['causes'].values())
    text = format_false_positives(document)
    assert text.splitlines()[2].startswith('3dprinter  @0.25  AP 1.000')


def test_a_missing_raw_room_or_mask_is_named(room: dict, tmp_path: Path) -> None:
    lidar = Path(room['lidar_path'])
    data = tmp_path / 'data'
    (data / 'points').mkdir(parents=True)
    copy = data / 'points' / lidar.name
    copy.write_bytes(lidar.read_bytes())
    with pytest.raises(InfoFileError, match='instance_mask.*no instance mask'):
        ScanFiles(str(copy))
    (data / 'instance_mask').mkdir()
    (data / 'instance_mask' / lidar.name).write_bytes(
        (room['data'] / 'instance_mask' / lidar.name).read_bytes())
    with pytest.raises(InfoFileError, match='factory_1/Annotations: no S3DIS Annotations'):
        ScanFiles(str(copy))
