"""A hook for the distributed-training test (tests/test_tools/test_experiments.py): every
process saves the samples it trained on and its parameters before and after training to
``<out_dir>/rank<R>.pth``."""
from pathlib import Path

import torch
from mmdet3d.registry import HOOKS
from mmengine.hooks import Hook
from mmengine.model import is_model_wrapper


def parameters(runner) -> dict[str, torch.Tensor]:
    """Copies of the model's parameters (inside its distributed wrapper)."""
    model = runner.model.module if is_model_wrapper(runner.model) else runner.model
    return {name: value.detach().clone() for name, value in model.named_parameters()}


@HOOKS.register_module()
class RankRecordHook(Hook):

    def __init__(self, out_dir: str):
        self.out_dir = Path(out_dir)
        self.seen: list[str] = []
        self.initial: dict[str, torch.Tensor] = {}

    def before_train(self, runner) -> None:
        self.initial = parameters(runner)

    def after_train_iter(self, runner, batch_idx, data_batch=None, outputs=None) -> None:
        self.seen += [Path(sample.lidar_path).name for sample in data_batch['data_samples']]

    def after_train(self, runner) -> None:
        self.out_dir.mkdir(parents=True, exist_ok=True)
        torch.save(
            dict(
                seen=self.seen,
                world_size=runner.world_size,
                initial=self.initial,
                final=parameters(runner)), self.out_dir / f'rank{runner.rank}.pth')
