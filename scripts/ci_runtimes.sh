#!/usr/bin/env bash
# onnxruntime-node for tests/test_runtimes.py (OpenVINO and tract come with the `dev` extra).
# Source it to export SINMDM_ORT_NODE (`. scripts/ci_runtimes.sh`), or run it and eval the
# line it prints. A failed install prints why and carries on: the test then skips, saying so.
# --onnxruntime-node-install=skip: the post-install step would fetch GPU binaries; the CPU one ships in the package.
sinmdm_ort_node="${TMPDIR:-/tmp}/sinmdm-ort-node"
if ! command -v npm >/dev/null 2>&1; then
  echo "ci_runtimes: npm not found, onnxruntime-node not installed" >&2
elif npm install --silent --no-audit --no-fund --prefix "$sinmdm_ort_node" onnxruntime-node \
    --onnxruntime-node-install=skip >/dev/null 2>&1; then
  export SINMDM_ORT_NODE="$sinmdm_ort_node"
  echo "export SINMDM_ORT_NODE=$sinmdm_ort_node"
else
  echo "ci_runtimes: npm install onnxruntime-node failed, its test will skip" >&2
fi
unset sinmdm_ort_node
