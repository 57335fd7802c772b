"""Distributed runs without a GPU: the gloo backend and a CPU model wrapper.

``tools/dist_train.sh`` and ``tools/dist_test.sh`` start the tools with torchrun and
``--launcher pytorch``. On GPUs mmengine initialises NCCL and wraps the model in
``MMDistributedDataParallel`` with the local rank as CUDA device. Without CUDA both steps fail
(mmengine's pytorch launcher calls ``torch.cuda.set_device``, and DistributedDataParallel refuses
device ids for a CPU model), so :func:`prepare_distributed` starts the gloo process group itself
(the Runner then skips its own initialisation) and selects :class:`CPUDistributedDataParallel`.
"""
import atexit
from datetime import timedelta

import torch
from mmengine.config import Config
from mmengine.model import MMDistributedDataParallel
from mmengine.registry import MODEL_WRAPPERS


@MODEL_WRAPPERS.register_module()
class CPUDistributedDataParallel(MMDistributedDataParallel):
    """``MMDistributedDataParallel`` for a model on the CPU: drops the ``device_ids`` that
    mmengine's Runner always passes (DistributedDataParallel accepts none for CPU modules)."""

    def __init__(self, module: torch.nn.Module, device_ids: list[int] | None = None, **kwargs):
        super().__init__(module=module, **kwargs)


def prepare_distributed(cfg: Config) -> None:
    """For ``--launcher pytorch`` on a machine without CUDA: start the gloo process group from
    torchrun's environment and use :class:`CPUDistributedDataParallel`. Does nothing otherwise
    (NCCL on GPUs, as configured in ``env_cfg.dist_cfg``)."""
    if cfg.get('launcher', 'none') != 'pytorch' or torch.cuda.is_available():
        return
    if not torch.distributed.is_initialized():
        torch.distributed.init_process_group(backend='gloo')
        atexit.register(_end_process_group)
    cfg.env_cfg.dist_cfg.backend = 'gloo'
    cfg.model_wrapper_cfg = dict(
        type='CPUDistributedDataParallel',
        broadcast_buffers=False,
        find_unused_parameters=cfg.get('find_unused_parameters', False))


def _end_process_group() -> None:
    """Tear the gloo group down before the interpreter exits, all processes together: left to
    the final clean-up, or torn down while a peer still writes its results, its threads can abort
    a finished process ("terminate called without an active exception"). A peer that died does
    not hold the exit up for longer than a minute."""
    if not torch.distributed.is_initialized():
        return
    try:
        torch.distributed.monitored_barrier(timeout=timedelta(seconds=60))
    except RuntimeError:
        pass  # a peer is gone: torchrun reports its failure, this process only has to end
    torch.distributed.destroy_process_group()
