"""The slowly moving teacher of self-training (``tools/adapt.py``): mmengine's ``EMAHook`` whose
average also carries over a checkpoint loaded with ``load_from``.

mmengine's ``EMAHook`` keeps an exponential moving average of the model's weights and saves it
as the checkpoint's ``state_dict`` (the student's own weights go to ``ema_state_dict``). It
restores both only when a run is resumed; a checkpoint loaded with ``load_from`` starts the
average afresh from its ``state_dict``. Self-training starts a new run at every refresh of
the pseudo-labels (a new training set), from the previous run's checkpoint: with this hook the
student continues from its own weights and the teacher from its average, as if the runs were
one.
"""
from mmengine.hooks import EMAHook
from mmdet3d.registry import HOOKS


@HOOKS.register_module()
class MeanTeacherEMAHook(EMAHook):
    """``EMAHook`` that restores the student and the average from any checkpoint holding an
    ``ema_state_dict``, resumed or loaded; other checkpoints start the average from their
    weights, as in ``EMAHook``."""

    def after_load_checkpoint(self, runner, checkpoint: dict) -> None:
        """Swap the student's weights back into ``state_dict`` (the Runner loads them into the
        model after this hook) and load the average into the EMA model."""
        if 'ema_state_dict' not in checkpoint:
            super().after_load_checkpoint(runner, checkpoint)
            return
        self._swap_ema_state_dict(checkpoint)
        self.ema_model.load_state_dict(checkpoint['ema_state_dict'], strict=self.strict_load)
