"""TR3D's sparse feature-pyramid neck (MinkowskiEngine)."""
from typing import Sequence

import MinkowskiEngine as ME
import torch
from mmdet3d.registry import MODELS
from mmengine.model import BaseModule
from torch import nn

from .mink_resnet import init_minkowski_weights


class CopyablePruning(ME.MinkowskiPruning):
    """MinkowskiEngine's pruning made copyable with ``copy.deepcopy`` (its function object
    cannot be pickled; it holds no state, so a copy is a new instance). mmengine's EMA hooks
    copy the whole model."""

    def __deepcopy__(self, memo: dict) -> 'CopyablePruning':
        copied = type(self)()
        copied.train(self.training)
        return copied


@MODELS.register_module()
class TR3DNeck(BaseModule):
    """Top-down sparse FPN over all backbone stages but the first; outputs all but the last level.

    With backbone outputs ``(s1, s2, s3, s4)`` it keeps ``(s2, s3, s4)``. Starting from ``s4``,
    each step upsamples with a generative transposed convolution (which creates new voxels around
    the coarse ones), adds the finer stage, and applies a 3x3x3 "lateral" block; an "out" block
    maps that level to ``out_channels``. For four stages this gives two levels (strides of ``s2``
    and ``s3``).

    With ``backbone_fine_level`` (not in TR3D) a third, finest level is added at the stride of
    ``s1``: the finest TR3D level is upsampled by a transposed convolution onto ``s1``'s own
    voxels (not a generative one, which would create locations around every coarse voxel),
    added to ``s1`` and passed through a lateral and an out block. It gives small objects
    locations half as far apart when the voxels are coarser than TR3D's 1 cm, at a fraction of
    the cost of finer voxels (``benchmarks/bench_model.py``).

    With ``generated_reach`` (not in TR3D) the voxels that a generative upsampling creates are
    kept only within that many voxels of the finer stage's own voxels (a Chebyshev distance in
    the finer stage's voxels; 0 keeps only the stage's own): TR3D's upsampling fills most of a
    room's volume, air included, and the blocks on that level cost the most of the model.

    Args:
        in_channels: channels of every backbone stage, the first one is used only for
            ``backbone_fine_level``.
        out_channels: channels of every output level.
        backbone_fine_level: add the finest level on the first stage's voxels.
        generated_reach: keep generated voxels within this many voxels of the finer stage's
            own; None keeps them all (TR3D).
    """

    def __init__(self,
                 in_channels: Sequence[int],
                 out_channels: int,
                 backbone_fine_level: bool = False,
                 generated_reach: int | None = None,
                 init_cfg=None):
        super().__init__(init_cfg)
        if generated_reach is not None and generated_reach < 0:
            raise ValueError(f'generated_reach must be >= 0 or None, got {generated_reach}')
        self.generated_reach = generated_reach
        self.pruning = CopyablePruning()
        channels = tuple(in_channels)[1:]
        if len(channels) < 2:
            raise ValueError(f'TR3DNeck needs at least 3 backbone stages, got {in_channels}')
        self.num_levels = len(channels) - 1
        for i in range(len(channels)):
            if i > 0:
                setattr(self, f'up_block_{i}', self._up_block(channels[i], channels[i - 1]))
            if i < self.num_levels:
                setattr(self, f'lateral_block_{i}', self._conv_block(channels[i], channels[i]))
                setattr(self, f'out_block_{i}', self._conv_block(channels[i], out_channels))
        self.backbone_fine_level = backbone_fine_level
        if backbone_fine_level:
            fine_channels = tuple(in_channels)[0]
            self.fine_up = ME.MinkowskiConvolutionTranspose(
                channels[0], fine_channels, kernel_size=3, stride=2, dimension=3)
            self.fine_up_norm = nn.Sequential(
                ME.MinkowskiBatchNorm(fine_channels), ME.MinkowskiReLU(inplace=True))
            self.fine_lateral_block = self._conv_block(fine_channels, fine_channels)
            self.fine_out_block = self._conv_block(fine_channels, out_channels)

    @staticmethod
    def _conv_block(in_channels: int, out_channels: int) -> nn.Sequential:
        return nn.Sequential(
            ME.MinkowskiConvolution(in_channels, out_channels, kernel_size=3, dimension=3),
            ME.MinkowskiBatchNorm(out_channels), ME.MinkowskiReLU(inplace=True))

    @staticmethod
    def _up_block(in_channels: int, out_channels: int) -> nn.Sequential:
        return nn.Sequential(
            ME.MinkowskiGenerativeConvolutionTranspose(
                in_channels, out_channels, kernel_size=3, stride=2, dimension=3),
            ME.MinkowskiBatchNorm(out_channels), ME.MinkowskiReLU(inplace=True))

    def init_weights(self) -> None:
        """Kaiming-normal convolution kernels, unit BatchNorm scale and zero shift."""
        init_minkowski_weights(self)

    def _near(self, generated: ME.SparseTensor, own: ME.SparseTensor) -> ME.SparseTensor:
        """``generated`` without the voxels farther than ``generated_reach`` voxels from every
        voxel of ``own`` (same scene, same tensor stride)."""
        if self.generated_reach is None:
            return generated
        keep = torch.isin(*voxel_keys(generated.C, own.C, self.generated_reach,
                                      own.tensor_stride[0]))
        return self.pruning(generated, keep) if not bool(keep.all()) else generated

    def forward(self, feats: Sequence[ME.SparseTensor]) -> list[ME.SparseTensor]:
        """Map backbone stage outputs to the output levels, finest first."""
        first, *inputs = feats
        x = inputs[-1]
        outs = []
        for i in range(self.num_levels - 1, -1, -1):
            x = inputs[i] + self._near(getattr(self, f'up_block_{i + 1}')(x), inputs[i])
            x = getattr(self, f'lateral_block_{i}')(x)
            outs.append(getattr(self, f'out_block_{i}')(x))
        if self.backbone_fine_level:
            x = first + self.fine_up_norm(self.fine_up(x, first.coordinate_map_key))
            outs.append(self.fine_out_block(self.fine_lateral_block(x)))
        return outs[::-1]


def voxel_keys(queries: torch.Tensor, anchors: torch.Tensor, reach: int,
               stride: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Integer keys of ``queries`` (Q, 4: scene, x, y, z) and of every voxel within ``reach``
    voxels of ``stride`` of the ``anchors`` (A, 4), such that a query's key is among the
    anchors' keys exactly when it is within reach of an anchor of its scene."""
    span = torch.arange(-reach, reach + 1, device=anchors.device) * stride
    offsets = torch.cartesian_prod(span, span, span).to(anchors.dtype)
    near = (anchors[:, None, 1:] + offsets[None]).reshape(-1, 3)
    scenes = anchors[:, :1].repeat_interleave(len(offsets), dim=0)
    near = torch.cat((scenes, near), dim=1)
    low = torch.minimum(near.min(dim=0).values, queries.min(dim=0).values)
    size = torch.maximum(near.max(dim=0).values, queries.max(dim=0).values) - low + 1

    def key(coordinates: torch.Tensor) -> torch.Tensor:
        shifted = (coordinates - low).long()
        return ((shifted[:, 0] * size[1] + shifted[:, 1]) * size[2] + shifted[:, 2]) * size[3] \
            + shifted[:, 3]

    return key(queries), key(near)
