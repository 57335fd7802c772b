"""TR3D's sparse feature-pyramid neck (MinkowskiEngine)."""
from typing import Sequence

import MinkowskiEngine as ME
from mmdet3d.registry import MODELS
from mmengine.model import BaseModule
from torch import nn

from .mink_resnet import init_minkowski_weights


@MODELS.register_module()
class TR3DNeck(BaseModule):
    """Top-down sparse FPN that drops the first backbone stage and outputs all but the last level.

    With backbone outputs ``(s1, s2, s3, s4)`` it keeps ``(s2, s3, s4)``. Starting from ``s4``,
    each step upsamples with a generative transposed convolution (which creates new voxels around
    the coarse ones), adds the finer stage, and applies a 3x3x3 "lateral" block; an "out" block
    maps that level to ``out_channels``. For four stages this gives two levels (strides of ``s2``
    and ``s3``).

    Args:
        in_channels: channels of every backbone stage, the first one is ignored.
        out_channels: channels of every output level.
    """

    def __init__(self, in_channels: Sequence[int], out_channels: int, init_cfg=None):
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
        """Map backbone stage outputs to ``num_levels`` output levels, finest first."""
        inputs = list(feats)[1:]
        x = inputs[-1]
        outs = []
        for i in range(self.num_levels - 1, -1, -1):
            x = inputs[i] + getattr(self, f'up_block_{i + 1}')(x)
            x = getattr(self, f'lateral_block_{i}')(x)
            outs.append(getattr(self, f'out_block_{i}')(x))
        return outs[::-1]
