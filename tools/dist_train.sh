#!/usr/bin/env bash
# Distributed training through torchrun and mmengine's pytorch launcher.
#   tools/dist_train.sh CONFIG NPROC [train.py args...]
# NPROC processes per node: one per GPU (NCCL); on a machine without CUDA, NPROC CPU processes
# (gloo, projects/synthdet/distributed.py). Multi-node: run it on every node with the same
# NNODES, MASTER_ADDR and PORT and that node's NODE_RANK (0 on the master), e.g.
#   NNODES=2 NODE_RANK=0 MASTER_ADDR=10.0.0.1 PORT=29500 tools/dist_train.sh configs/tr3d/exp3.py 4
# PYTHON chooses the interpreter (default python).
set -euo pipefail

CONFIG=${1:?usage: tools/dist_train.sh CONFIG NPROC [train.py args...]}
NPROC=${2:?usage: tools/dist_train.sh CONFIG NPROC [train.py args...]}
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
    "$ROOT/tools/train.py" "$CONFIG" --launcher pytorch "$@"
