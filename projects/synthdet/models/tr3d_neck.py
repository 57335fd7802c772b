"""TR3D's sparse feature-pyramid neck (MinkowskiEngine)."""
from typing import Sequence

import MinkowskiEngine as ME
from mmdet3d.registry import MODELS
from mmengine.model import BaseModule
from torch import nn

from .mink_resnet import init_minkowski_weights


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

    Args:
        in_channels: channels of every backbone stage, the first one is used only for
            ``backbone_fine_level``.
        out_channels: channels of every output level.
        backbone_fine_level: add the finest level on the first stage's voxels.
    """

    def __init__(self,
                 in_channels: Sequence[int],
                 out_channels: int,
                 backbone_fine_level: bool = False,
                 init_cfg=None):
        super().__init__(init_cfg)
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

    def forward(self, feats: Sequence[ME.SparseTensor]) -> list[ME.SparseTensor]:
        """Map backbone stage outputs to the output levels, finest first."""
        first, *inputs = feats
        x = inputs[-1]
        outs = []
        for i in range(self.num_levels - 1, -1, -1):
            x = inputs[i] + getattr(self, f'up_block_{i + 1}')(x)
            x = getattr(self, f'lateral_block_{i}')(x)
            outs.append(getattr(self, f'out_block_{i}')(x))
        if self.backbone_fine_level:
            x = first + self.fine_up_norm(self.fine_up(x, first.coordinate_map_key))
            outs.append(self.fine_out_block(self.fine_lateral_block(x)))
        return outs[::-1]
