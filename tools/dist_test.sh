#!/usr/bin/env bash
# Distributed testing (Table 3) through torchrun and mmengine's pytorch launcher.
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
NNODES=${NNODES:-1}
NODE_RANK=${NODE_RANK:-0}
PORT=${PORT:-29500}
MASTER_ADDR=${MASTER_ADDR:-127.0.0.1}
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
PYTHON=${PYTHON:-python}

PYTHONPATH="$ROOT${PYTHONPATH:+:$PYTHONPATH}" \
exec "$PYTHON" -m torch.distributed.run \
    --nnodes="$NNODES" \
    --node_rank="$NODE_RANK" \
    --master_addr="$MASTER_ADDR" \
    --master_port="$PORT" \
    --nproc_per_node="$NPROC" \
    "$ROOT/tools/test.py" "$CONFIG" "$CHECKPOINT" --launcher pytorch "$@"
