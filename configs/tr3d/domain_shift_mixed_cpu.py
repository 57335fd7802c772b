# The domain-shift benchmark's mixed-profile model (benchmarks/bench_domain_shift.py):
# domain_shift_cpu.py trained on the rooms of the generator's default mix (area 12) with the
# robustness augmentations of _base_/s3dis-synthdet.py, tested on the mixed test rooms (area 28).
_base_ = ['./domain_shift_cpu.py']
from projects.synthdet.config_helpers import area_datasets, area_info_file  # noqa: E402
from projects.synthdet.config_helpers import with_robustness  # noqa: E402

train_pipeline = with_robustness(_base_.train_pipeline, _base_.robust_augmentations)
robustness = True

train_area = [12]
test_area = 28

train_dataloader = dict(
    dataset=dict(
        dataset=dict(
            datasets=area_datasets(
                dict(
                    _base_.train_area_dataset, data_root=_base_.data_root,
                    pipeline=train_pipeline), train_area, _base_.metainfo))))
test_dataloader = dict(dataset=dict(ann_file=area_info_file(test_area)))
