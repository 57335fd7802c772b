#!/usr/bin/env bash
# Distributed testing (Table 3) through torchrun and mmengine's pytorch launcher
# (tools/dist_run.sh).
#   tools/dist_test.sh CONFIG CHECKPOINT NPROC [test.py args...]
# NPROC processes per node, one per GPU (NCCL) or, without CUDA, CPU processes (gloo). The test
# set is split between the processes and the metrics are computed once on all predictions.
# Multi-node and PYTHON: as tools/dist_train.sh.
set -euo pipefail

USAGE='usage: tools/dist_test.sh CONFIG CHECKPOINT NPROC [test.py args...]'
CONFIG=${1:?$USAGE}
CHECKPOINT=${2:?$USAGE}
NPROC=${3:?$USAGE}
shift 3
exec "$(dirname "${BASH_SOURCE[0]}")/dist_run.sh" test.py "$NPROC" "$CONFIG" "$CHECKPOINT" "$@"
