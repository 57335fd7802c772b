"""One box for an object the detector splits into several: an L-shaped sofa detected as three
or four sofas, a long table as two tables.

The rule (a config's ``fragment_merge = dict(classes=(...), min_share=...)``): among the
detections of one of ``classes`` that score at least the output threshold, a box whose
axis-aligned overlap with a higher-scoring box of its class holds at least ``min_share`` of the
smaller box's volume is a fragment of it: the higher box grows to hold both (their axis-aligned
hull) and keeps its score; the fragment goes. A grown box takes the next fragments in the same
way. Boxes of other classes and boxes below the threshold stay as they are. Chairs are left
out in the configs: chairs stand close together, and two overlapping chair boxes are more often
two chairs than one.
"""
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from .windows import Detections


@dataclass(frozen=True)
class FragmentRule:
    """The classes whose fragments merge and the overlap that makes a fragment."""

    classes: tuple[str, ...]
    min_share: float


def fragment_rule_from_config(cfg: Mapping) -> FragmentRule | None:
    """The ``fragment_merge`` of a model config; ``None`` when it has none. ``ValueError`` for
    a share outside (0, 1] or classes that are not a list of names."""
    rule = cfg.get('fragment_merge')
    if rule is None:
        return None
    classes, share = rule.get('classes'), rule.get('min_share')
    if not isinstance(classes, (list, tuple)) or not all(isinstance(c, str) for c in classes):
        raise ValueError(f'fragment_merge.classes {classes!r}: expected a list of class names')
    if not isinstance(share, (int, float)) or not 0 < share <= 1:
        raise ValueError(f'fragment_merge.min_share {share!r}: expected a number in (0, 1]')
    return FragmentRule(tuple(classes), float(share))


def _corners(boxes: np.ndarray) -> np.ndarray:
    """``(K, 2, 3)`` low and high corners of gravity-centre boxes ``(K, 7)``; a box turned by a
    quarter turn (odd multiple of 90 degrees) has its x and y sizes swapped."""
    sizes = boxes[:, 3:6].copy()
    turned = np.abs(np.sin(boxes[:, 6])) > np.sqrt(0.5)
    sizes[turned] = sizes[turned][:, [1, 0, 2]]
    return np.stack([boxes[:, :3] - sizes / 2, boxes[:, :3] + sizes / 2], axis=1)


def _merge_class(corners: np.ndarray,
                 min_share: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Merge the fragments among ``corners`` (K, 2, 3) in descending score order; returns for
    each box whether it is kept, whether it took a fragment and its grown corners."""
    alive = np.ones(len(corners), dtype=bool)
    grew = np.zeros(len(corners), dtype=bool)
    grown = corners.copy()
    for leader in range(len(corners)):
        if not alive[leader]:
            continue
        absorbed = True
        while absorbed:  # a grown leader may reach further fragments
            absorbed = False
            for other in np.flatnonzero(alive[leader + 1:]) + leader + 1:
                low = np.maximum(grown[leader, 0], grown[other, 0])
                high = np.minimum(grown[leader, 1], grown[other, 1])
                overlap = np.prod(np.clip(high - low, 0, None))
                smaller = min(np.prod(grown[leader, 1] - grown[leader, 0]),
                              np.prod(grown[other, 1] - grown[other, 0]))
                if smaller > 0 and overlap >= min_share * smaller:
                    grown[leader, 0] = np.minimum(grown[leader, 0], grown[other, 0])
                    grown[leader, 1] = np.maximum(grown[leader, 1], grown[other, 1])
                    alive[other] = False
                    grew[leader] = True
                    absorbed = True
    return alive, grew, grown


def merge_fragments(detections: Detections, class_names: Sequence[str], rule: FragmentRule,
                    score_thr: float) -> Detections:
    """``detections`` with the fragments of the rule's classes merged among the boxes scoring
    at least ``score_thr`` (module doc); ``class_names`` names the labels. The result is in
    descending score order; a merged box is axis-aligned (yaw 0)."""
    keep = np.ones(len(detections.scores), dtype=bool)
    boxes = detections.boxes.copy()
    for label, name in enumerate(class_names):
        if name not in rule.classes:
            continue
        rows = np.flatnonzero((detections.labels == label) & (detections.scores >= score_thr))
        rows = rows[np.argsort(-detections.scores[rows], kind='stable')]
        if len(rows) < 2:
            continue
        alive, grew, grown = _merge_class(_corners(boxes[rows]), rule.min_share)
        for row, (low, high) in zip(rows[grew], grown[grew]):
            boxes[row] = np.concatenate([(low + high) / 2, high - low, [0.0]])
        keep[rows[~alive]] = False
    result = Detections(boxes, detections.scores, detections.labels).select(keep)
    return result.select(np.argsort(-result.scores, kind='stable'))
