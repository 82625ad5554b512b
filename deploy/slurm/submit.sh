#!/usr/bin/env bash
# Submits the dataset array (TASKS tasks, default 8) and the merge, which runs after every task
# has succeeded. DATASET_DIR, DATASET_ARGS (and VKDIFF) are passed on to the jobs.
#
#   DATASET_DIR=/shared/mushrooms DATASET_ARGS=deploy/paper.args TASKS=16 deploy/slurm/submit.sh
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
: "${DATASET_DIR:?set DATASET_DIR}" "${DATASET_ARGS:?set DATASET_ARGS}"
export DATASET_DIR DATASET_ARGS="$(realpath "$DATASET_ARGS")"
tasks=${TASKS:-8}
array=$(sbatch --parsable --export=ALL --array="0-$((tasks - 1))" "$here/dataset.sbatch")
merge=$(sbatch --parsable --export=ALL --dependency="afterok:${array%%;*}" "$here/merge.sbatch")
echo "dataset array ${array%%;*} ($tasks tasks), merge $merge"
