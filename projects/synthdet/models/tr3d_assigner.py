"""TR3D's location-to-box assignment rule."""
from typing import Sequence

import torch
from torch import Tensor


@torch.no_grad()
def tr3d_assign(points: Sequence[Tensor], gt_centers: Tensor, gt_labels: Tensor,
                label2level: Sequence[int], top_k: int) -> Tensor:
    """Assign head locations of all levels to ground-truth boxes, as TR3D does.

    Each box is handled on one level only, ``label2level[label]``. Among that level's locations,
    the ``top_k`` nearest to the box centre are the box's candidates (fewer when the level has
    fewer locations; distance ties at the k-th place are broken by location order). A location
    that is a candidate of several boxes goes to the box whose centre is nearest. There is no
    box-containment condition: a small box still gets its ``top_k`` locations.

    Args:
        points: per level, (N_l, 3) location coordinates in metres.
        gt_centers: (M, 3) box centres (gravity centres) in metres.
        gt_labels: (M,) class indices.
        label2level: output level of every class.
        top_k: positives per box (TR3D's ``pts_center_threshold``).

    Returns:
        (sum N_l,) long tensor: index of the assigned box per location (levels concatenated in
        order), -1 for negatives.
    """
    levels = torch.cat([
        torch.full((len(p), ), i, dtype=torch.long, device=p.device) for i, p in enumerate(points)
    ])
    all_points = torch.cat(list(points))
    assigned = torch.full((len(all_points), ), -1, dtype=torch.long, device=all_points.device)
    if len(gt_labels) == 0 or len(all_points) == 0:
        return assigned
    if int(gt_labels.max()) >= len(label2level):
        raise ValueError(f'label {int(gt_labels.max())} has no entry in label2level '
                         f'{tuple(label2level)}')
    box_levels = torch.as_tensor(label2level, device=gt_labels.device)[gt_labels]
    distances = (all_points[:, None, :] - gt_centers[None, :, :].to(all_points)).pow(2).sum(-1)
    on_level = levels[:, None] == box_levels[None, :].to(levels.device)
    distances = torch.where(on_level, distances, torch.full_like(distances, float('inf')))

    nearest = distances.topk(min(top_k, len(all_points)), dim=0, largest=False).indices
    candidate = torch.zeros_like(on_level).scatter_(0, nearest, True) & on_level
    distances = torch.where(candidate, distances, torch.full_like(distances, float('inf')))
    min_distance, box_index = distances.min(dim=1)
    return torch.where(torch.isfinite(min_distance), box_index, assigned)
