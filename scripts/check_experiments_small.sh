#!/usr/bin/env bash
# The commands of docs/experiments.md (experiments 1 and 3 with the real S3DIS), run on a CPU at
# the smallest scale: a stand-in for S3DIS areas 1-6 (one small room per area in S3DIS naming,
# plus Area_5/hallway_6 with the known stray byte, from tests/s3dis_fixtures.py), generated areas
# 7-9 of one 50,000-point room each, and the published configs with only the loader and the
# schedule shrunk (SMALL below: batch 2, no repeat, 2 epochs, no loader workers). The numbers
# mean nothing; the run shows that every command works and what it writes.
#   bash scripts/check_experiments_small.sh [WORK]      (default /tmp/synthdet_experiments)
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$ROOT"
WORK=${1:-/tmp/synthdet_experiments}
PY=${PY:-$ROOT/.venv/bin/python}
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-1} PYTHON=$PY
DATA=$WORK/data/s3dis
RAW=$DATA/Stanford3dDataset_v1.2_Aligned_Version
SMALL=(train_dataloader.batch_size=2 train_dataloader.num_workers=0
       train_dataloader.persistent_workers=False train_dataloader.dataset.times=1
       train_cfg.max_epochs=2 val_dataloader.num_workers=0 val_dataloader.persistent_workers=False
       test_dataloader.num_workers=0 test_dataloader.persistent_workers=False)
roots() {  # data_root of every dataset of a config with N training areas
    local options=(val_dataloader.dataset.data_root=$DATA/ test_dataloader.dataset.data_root=$DATA/)
    for ((i = 0; i < $1; i++)); do
        options+=(train_dataloader.dataset.dataset.datasets.$i.data_root=$DATA/)
    done
    echo "${options[@]}"
}
step() { echo; echo "=== $*"; }

rm -rf "$WORK" && mkdir -p "$RAW"
step '1. the stand-in for the S3DIS download (areas 1-6)'
"$PY" - "$DATA" <<'PYEOF'
import sys
from pathlib import Path
from tests.s3dis_fixtures import write_synthetic_area
from tests.s3dis_fixtures import S3DIS_OBJECTS, write_hallway_6
root = Path(sys.argv[1])
for area in range(1, 7):
    write_synthetic_area(root, area, n_rooms=2 if area == 5 else 1, seed=area,
                         classes=S3DIS_OBJECTS, points_per_object=400)
write_hallway_6(root / 'Stanford3dDataset_v1.2_Aligned_Version')
PYEOF
step '2. generate areas 7-9'
"$PY" -m generator --out "$RAW" --areas 7 8 9 --rooms-per-area 1 --points 50000 --seed 0 \
    --workers 2 --quiet
step '3. convert areas 1-9 and print Table 1'
"$PY" tools/create_data.py s3dis --root-path "$DATA" --out-dir "$DATA" --workers 2
"$PY" tools/dataset_stats.py "$DATA" --out "$WORK/table1.json"
step '4. train experiment 1 (one process) and experiment 3 (two processes, gloo)'
"$PY" tools/train.py configs/tr3d/exp1.py --work-dir "$WORK/exp1" \
    --cfg-options "${SMALL[@]}" $(roots 5)
PORT=29531 bash tools/dist_train.sh configs/tr3d/exp3.py 2 --work-dir "$WORK/exp3" \
    --auto-scale-lr --cfg-options "${SMALL[@]}" $(roots 8)
step '4b. experiment 3 fine-tuned from a checkpoint of TR3D S3DIS layout (here: exp1 above)'
"$PY" tools/train.py configs/tr3d/exp3_finetune.py --work-dir "$WORK/exp3_finetune" \
    --cfg-options "${SMALL[@]}" $(roots 8) train_cfg.max_epochs=1 \
    load_from="$(ls "$WORK"/exp1/best_mAP_0.25_epoch_*.pth)"
step '5. test: Table 3 (one process, then two)'
"$PY" tools/test.py configs/tr3d/exp1.py "$(ls "$WORK"/exp1/best_mAP_0.25_epoch_*.pth)" \
    --work-dir "$WORK/exp1/test" --show-dir "$WORK/exp1/test/show" --cfg-options \
    "${SMALL[@]}" $(roots 5)
PORT=29532 bash tools/dist_test.sh configs/tr3d/exp3.py \
    "$(ls "$WORK"/exp3/best_mAP_0.25_epoch_*.pth)" 2 --work-dir "$WORK/exp3/test" \
    --cfg-options "${SMALL[@]}" $(roots 8)
step '6. Table 4: predict area 5 with both models and count'
"$PY" tools/predict.py configs/tr3d/exp1.py "$(ls "$WORK"/exp1/best_mAP_0.25_epoch_*.pth)" \
    "$DATA"/points/Area_5_*.bin --out "$WORK/predictions/exp1"
"$PY" tools/predict.py configs/tr3d/exp3.py "$(ls "$WORK"/exp3/best_mAP_0.25_epoch_*.pth)" \
    "$DATA"/points/Area_5_*.bin --out "$WORK/predictions/exp3"
"$PY" tools/count_table.py "$WORK/predictions/exp1" "$WORK/predictions/exp3" \
    --infos "$DATA/s3dis_infos_Area_5.pkl" --out "$WORK/table4.json"
step "done: $WORK"
