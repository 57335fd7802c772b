# synthdet: `make demo` runs the main job, `make test` runs the tests; both install the stack first.
SHELL := /bin/bash
VENV ?= .venv
PY := $(VENV)/bin/python
PYTEST_ARGS ?=
# test processes (pytest-xdist; one file's tests stay in one process, sharing its fixtures);
# PYTEST_WORKERS=0 runs them all in this process
PYTEST_WORKERS ?= 2

.PHONY: setup test demo exp2-cpu bench

setup:
	bash scripts/setup.sh

# pytest exits 5 when it collected no test: that is a failure here, with a message saying so.
# One OpenMP thread per process: the tests compare results across processes, and several
# threads make MinkowskiEngine's CPU sums run in a varying order.
test: export OMP_NUM_THREADS ?= 1
test: setup
	@$(PY) -m pytest -n $(PYTEST_WORKERS) --dist loadfile $(PYTEST_ARGS); rc=$$?; \
	if [ $$rc -eq 5 ]; then echo "make test: pytest collected no tests (exit 5)"; fi; exit $$rc

# The whole pipeline on small generated data (tools/demo.py; measured times in docs/results.md), ending
# with work_dirs/demo/REPORT.md. Resumable: rerun to continue. DEMO_ARGS="--size tiny --threads 1"
# for a quick run. One OpenMP thread per step by default (see EXP2_THREADS below).
DEMO_ARGS ?= --threads 1
demo: setup
	$(PY) tools/demo.py $(DEMO_ARGS)

# Experiment 2 at CPU scale (docs/experiments.md, figures in docs/results.md): 3 generated areas x 50 rooms x 1M points in
# data/s3dis, their annotations checked against the objects' boxes (tools/check_annotations.py),
# train areas 7, 8 and test area 9 with configs/tr3d/exp2_cpu.py. Every step resumes: finished
# rooms are kept, training continues from the newest checkpoint of work_dirs/exp2_cpu, and the
# test uses the final epoch's checkpoint (named in last_checkpoint), on all of area 9 and then on
# the rooms of each generator sensor that scanned some of them (tools/dataset_stats.py --sensors,
# tools/test.py --sensor), each test with its box-fit table
# (--box-fit), the area-9 test also with what its false positives hit (--false-positives).
# About 2 hours on an idle 2-core machine in the default 2 processes (12 epochs of 8-9 min with
# their validation). Rooms written by an older generator are kept as they are:
# empty data/s3dis to regenerate them.
EXP2_DATA ?= data/s3dis
# the generator profile of the rooms (generator/profiles): mixed_rooms puts offices, meeting
# rooms, living rooms and bedrooms beside the factory rooms, so that the model learns what is not
# a YuMi or a 3D printer (docs/generator.md, "Room kinds"); EXP2_PROFILE= for factory rooms only
EXP2_PROFILE ?= mixed_rooms
EXP2_WORK ?= work_dirs/exp2_cpu
# the config trained and tested: exp2_cpu.py or a variant of it
EXP2_CONFIG ?= configs/tr3d/exp2_cpu.py
# One OpenMP thread per process by default: on a busy machine torch's default (all cores)
# oversubscribes the cores. With EXP2_PROCS=1, set EXP2_THREADS=2 on an idle 2-core machine.
EXP2_THREADS ?= 1
# Training processes (tools/dist_train.sh, gloo on the CPU) sharing the batch of 4 rooms: 1, 2 or
# 4. On an idle 2-core machine 2 processes with EXP2_THREADS=1 train at 4.6 s per iteration
# against 6.3 s for one process with 2 threads (docs/history.md) and end at the same accuracy;
# the tests stay one process.
EXP2_PROCS ?= 2
ifneq ($(filter-out 1 2 4,$(EXP2_PROCS)),)
$(error EXP2_PROCS=$(EXP2_PROCS): must be 1, 2 or 4, to split the batch of 4 rooms evenly)
endif
ifeq ($(EXP2_PROCS),1)
EXP2_TRAIN = $(PY) tools/train.py $(EXP2_CONFIG)
EXP2_BATCH_OPTIONS =
else
EXP2_TRAIN = PYTHON=$(PY) tools/dist_train.sh $(EXP2_CONFIG) $(EXP2_PROCS)
EXP2_BATCH_OPTIONS = train_dataloader.batch_size=$(shell expr 4 / $(EXP2_PROCS))
endif
# the config's data root (data/s3dis/) replaced by EXP2_DATA in every dataset
EXP2_DATA_OPTIONS = $(foreach key,train_dataloader.dataset.dataset.datasets.0 \
    train_dataloader.dataset.dataset.datasets.1 val_dataloader.dataset test_dataloader.dataset,\
    $(key).data_root=$(EXP2_DATA)/)
# more --cfg-options for the training and the tests, e.g. a variant of the model
# (EXP2_OPTIONS="model.bbox_head.label2level=[2,1,1,1,1]"); use a new EXP2_WORK for each variant
EXP2_OPTIONS ?=
EXP2_CFG_OPTIONS = $(EXP2_DATA_OPTIONS) $(EXP2_OPTIONS)
# a folder of your own labelled scans (X.ply with X.labels.json beside it, docs/evaluation.md):
# when set, the run ends with their evaluation by the final checkpoint (tools/eval_scans.py),
# one pass into $(EXP2_WORK)/real_scans and with --tta into $(EXP2_WORK)/real_scans_tta,
# e.g. make exp2-cpu REAL_SCANS=~/labelled-scans
REAL_SCANS ?=
exp2-cpu: export OMP_NUM_THREADS = $(EXP2_THREADS)
exp2-cpu: setup
	$(PY) -m generator --out $(EXP2_DATA)/Stanford3dDataset_v1.2_Aligned_Version --areas 7 8 9 \
	    --rooms-per-area 50 --points 1000000 --seed 0 --workers 2 \
	    $(if $(strip $(EXP2_PROFILE)),--profile $(EXP2_PROFILE))
	$(PY) tools/check_annotations.py $(EXP2_DATA)/Stanford3dDataset_v1.2_Aligned_Version --areas 7 8 9
	$(PY) tools/create_data.py s3dis --root-path $(EXP2_DATA) --out-dir $(EXP2_DATA) --areas 7 8 9 --workers 2
	$(PY) tools/dataset_stats.py $(EXP2_DATA) --areas 7 8 9
	$(EXP2_TRAIN) --work-dir $(EXP2_WORK) \
	    $$(ls $(EXP2_WORK)/epoch_*.pth >/dev/null 2>&1 && echo --resume) \
	    --cfg-options $(EXP2_CFG_OPTIONS) $(EXP2_BATCH_OPTIONS)
	$(PY) tools/test.py $(EXP2_CONFIG) $$(cat $(EXP2_WORK)/last_checkpoint) \
	    --work-dir $(EXP2_WORK)/test --box-fit --false-positives --cfg-options $(EXP2_CFG_OPTIONS)
	$(PY) tools/test.py $(EXP2_CONFIG) $$(cat $(EXP2_WORK)/last_checkpoint) --tta \
	    --work-dir $(EXP2_WORK)/test_tta --box-fit --false-positives --cfg-options $(EXP2_CFG_OPTIONS)
	sensors=$$($(PY) tools/dataset_stats.py $(EXP2_DATA) --areas 9 --sensors) || exit 1; \
	for sensor in $$sensors; do \
	    $(PY) tools/test.py $(EXP2_CONFIG) $$(cat $(EXP2_WORK)/last_checkpoint) \
	        --sensor $$sensor --work-dir $(EXP2_WORK)/test_$$sensor --box-fit \
	        --cfg-options $(EXP2_CFG_OPTIONS) || exit 1; \
	done
ifneq ($(strip $(REAL_SCANS)),)
	$(PY) tools/eval_scans.py $(EXP2_CONFIG) $$(cat $(EXP2_WORK)/last_checkpoint) $(REAL_SCANS) \
	    --out $(EXP2_WORK)/real_scans --cfg-options $(EXP2_CFG_OPTIONS)
	$(PY) tools/eval_scans.py $(EXP2_CONFIG) $$(cat $(EXP2_WORK)/last_checkpoint) $(REAL_SCANS) \
	    --tta --out $(EXP2_WORK)/real_scans_tta --cfg-options $(EXP2_CFG_OPTIONS)
endif

# Every benchmarks/bench_*.py, one after the other; each full output is kept in
# docs/benchmarks/<name>.txt and docs/benchmarks.md is written from them.
# BENCH_ARGS="--only scanner convert" runs a subset (the others keep their earlier outputs).
# The domain-shift benchmark (about 1.5 h on 2 cores: data, two trainings, 16 tests) runs only
# when named: BENCH_ARGS="--only domain_shift" (docs/results.md, "Domain shift").
BENCH_ARGS ?=
bench: setup
	$(PY) tools/collect_benchmarks.py $(BENCH_ARGS)
