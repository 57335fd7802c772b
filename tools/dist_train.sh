#!/usr/bin/env bash
# Distributed training through torchrun and mmengine's pytorch launcher (tools/dist_run.sh).
#   tools/dist_train.sh CONFIG NPROC [train.py args...]
# NPROC processes per node: one per GPU (NCCL); on a machine without CUDA, NPROC CPU processes
# (gloo). Multi-node: run it on every node with the same NNODES, MASTER_ADDR and PORT and that
# node's NODE_RANK (0 on the master), e.g.
#   NNODES=2 NODE_RANK=0 MASTER_ADDR=10.0.0.1 PORT=29500 tools/dist_train.sh configs/tr3d/exp3.py 4
# PYTHON chooses the interpreter (default python).
set -euo pipefail

USAGE='usage: tools/dist_train.sh CONFIG NPROC [train.py args...]'
CONFIG=${1:?$USAGE}
NPROC=${2:?$USAGE}
shift 2
exec "$(dirname "${BASH_SOURCE[0]}")/dist_run.sh" train.py "$NPROC" "$CONFIG" "$@"
