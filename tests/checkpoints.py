"""Checkpoints of untrained models for the tests that load one."""
from __future__ import annotations

from pathlib import Path


def initial_checkpoint(config: Path, path: Path, classes: list[str] | None = None) -> Path:
    """Write to ``path`` a checkpoint of ``config``'s model with its initial weights (seeded),
    its meta naming ``classes`` (default: those of the config's test dataset); returns ``path``."""
    import torch
    from mmdet3d.apis import init_model
    from mmengine.config import Config
    torch.manual_seed(0)
    cfg = Config.fromfile(str(config))
    model = init_model(cfg, None, device='cpu')
    if classes is None:
        classes = list(cfg.test_dataloader.dataset.metainfo['classes'])
    torch.save({'state_dict': model.state_dict(), 'meta': {'dataset_meta': {'classes': classes}}},
               path)
    return path
