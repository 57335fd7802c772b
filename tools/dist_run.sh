#!/usr/bin/env bash
# Start a tool in NPROC processes per node through torchrun, with mmengine's pytorch launcher;
# used by tools/dist_train.sh and tools/dist_test.sh.
#   tools/dist_run.sh TOOL NPROC [tool args...]      (TOOL: train.py or test.py)
# NPROC processes per node: one per GPU (NCCL); without CUDA, CPU processes (gloo,
# projects/synthdet/distributed.py). Multi-node: the same NNODES, MASTER_ADDR and PORT on
# every node and that node's NODE_RANK (0 on the master). PYTHON: the interpreter (python).
set -euo pipefail

USAGE='usage: tools/dist_run.sh TOOL NPROC [tool args...]'
TOOL=${1:?$USAGE}
NPROC=${2:?$USAGE}
shift 2
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
    "$ROOT/tools/$TOOL" "$@" --launcher pytorch
