"""TR3D's sparse ResNet backbone (MinkowskiEngine)."""
from typing import Sequence

import MinkowskiEngine as ME
from MinkowskiEngine.modules.resnet_block import BasicBlock
from mmdet3d.registry import MODELS
from mmengine.model import BaseModule
from torch import nn


def init_minkowski_weights(root: nn.Module) -> None:
    """Kaiming-normal kernels for every sparse convolution in ``root``, unit BatchNorm scale and
    zero shift (TR3D's initialisation of its backbone and neck)."""
    for module in root.modules():
        if isinstance(module, ME.MinkowskiConvolution):
            ME.utils.kaiming_normal_(module.kernel, mode='fan_out', nonlinearity='relu')
        if isinstance(module, ME.MinkowskiBatchNorm):
            nn.init.constant_(module.bn.weight, 1)
            nn.init.constant_(module.bn.bias, 0)


@MODELS.register_module()
class TR3DMinkResNet(BaseModule):
    """Sparse ResNet with BasicBlocks and narrow stages, as published for TR3D.

    A stride-2 3x3x3 stem convolution with BatchNorm and ReLU, a stride-2 max-pool, then
    ``num_stages`` residual stages that each start with stride 2. TR3D's S3DIS model uses depth 34
    (blocks 3, 4, 6, 3) and planes (64, 128, 128, 128).

    Args:
        in_channels: input feature channels (3 for RGB).
        depth: ResNet depth, 18 or 34 (BasicBlock variants).
        num_planes: output channels of each stage.
        num_stages: number of stages to build and return, 1 to 4.
    """
    stage_blocks = {18: (2, 2, 2, 2), 34: (3, 4, 6, 3)}
    stem_planes = 64

    def __init__(self,
                 in_channels: int = 3,
                 depth: int = 34,
                 num_planes: Sequence[int] = (64, 128, 128, 128),
                 num_stages: int = 4,
                 init_cfg=None):
        super().__init__(init_cfg)
        if depth not in self.stage_blocks:
            raise KeyError(f'depth must be one of {sorted(self.stage_blocks)}, got {depth}')
        if not 1 <= num_stages <= 4 or len(num_planes) < num_stages:
            raise ValueError(f'need 1 <= num_stages <= 4 and num_planes for every stage, got '
                             f'num_stages={num_stages}, num_planes={tuple(num_planes)}')
        self.num_stages = num_stages
        self.conv1 = ME.MinkowskiConvolution(
            in_channels, self.stem_planes, kernel_size=3, stride=2, dimension=3)
        self.norm1 = ME.MinkowskiBatchNorm(self.stem_planes)
        self.relu = ME.MinkowskiReLU(inplace=True)
        self.maxpool = ME.MinkowskiMaxPooling(kernel_size=2, stride=2, dimension=3)
        inplanes = self.stem_planes
        for i in range(num_stages):
            setattr(self, f'layer{i + 1}',
                    self._make_stage(inplanes, num_planes[i], self.stage_blocks[depth][i]))
            inplanes = num_planes[i]

    @staticmethod
    def _make_stage(inplanes: int, planes: int, blocks: int) -> nn.Sequential:
        """A residual stage whose first block has stride 2 and a 1x1 projection shortcut."""
        downsample = nn.Sequential(
            ME.MinkowskiConvolution(inplanes, planes, kernel_size=1, stride=2, dimension=3),
            ME.MinkowskiBatchNorm(planes))
        layers = [BasicBlock(inplanes, planes, stride=2, downsample=downsample, dimension=3)]
        layers += [BasicBlock(planes, planes, stride=1, dimension=3) for _ in range(1, blocks)]
        return nn.Sequential(*layers)

    def init_weights(self) -> None:
        """Kaiming-normal convolution kernels, unit BatchNorm scale and zero shift."""
        init_minkowski_weights(self)

    def forward(self, x: ME.SparseTensor) -> list[ME.SparseTensor]:
        """Return the output of every stage (tensor strides 8, 16, 32, 64 voxels)."""
        x = self.maxpool(self.relu(self.norm1(self.conv1(x))))
        outs = []
        for i in range(self.num_stages):
            x = getattr(self, f'layer{i + 1}')(x)
            outs.append(x)
        return outs
