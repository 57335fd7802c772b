"""synthdet models (registered with mmdet3d on import): TR3D detector, parts and loss, and the
mean teacher's EMA hook of self-training."""
from .losses import TR3DAxisAlignedIoULoss
from .mean_teacher import MeanTeacherEMAHook
from .mink_resnet import TR3DMinkResNet
from .tr3d import TR3DDetector
from .tr3d_assigner import tr3d_assign
from .tr3d_head import TR3DHead
from .tr3d_neck import TR3DNeck
from .tta import SynthdetTTAModel

__all__ = [
    'TR3DAxisAlignedIoULoss', 'TR3DMinkResNet', 'TR3DDetector', 'tr3d_assign', 'TR3DHead',
    'TR3DNeck', 'SynthdetTTAModel', 'MeanTeacherEMAHook'
]
