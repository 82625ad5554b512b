#!/usr/bin/env bash
# The arguments as a ConfigMap, the Indexed Job, and the merge once the Job is complete.
#   deploy/kubernetes/run.sh deploy/paper.args
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
args=${1:?usage: run.sh ARGS_FILE}
kubectl create configmap vkdiff-dataset-args --from-file=dataset.args="$args" --dry-run=client -o yaml | kubectl apply -f -
kubectl apply -f "$here/dataset-job.yaml"
kubectl wait --for=condition=complete --timeout=-1s job/vkdiff-dataset
kubectl apply -f "$here/merge-job.yaml"
kubectl wait --for=condition=complete --timeout=1h job/vkdiff-merge
