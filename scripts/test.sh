#!/usr/bin/env bash
# Install sinmdm with every extra into .venv (torch's CPU wheel first) and run the tests.
# The HTML-viewer test also wants Debian's chromium (apt-get install chromium); it skips without it.
set -euo pipefail
cd "$(dirname "$0")/.."
export OMP_NUM_THREADS="${OMP_NUM_THREADS:-2}" MKL_NUM_THREADS="${MKL_NUM_THREADS:-2}" OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS:-2}"
[ -d .venv ] || python3 -m venv .venv
. .venv/bin/activate
python -m pip install -q --upgrade pip
# TORCH_INDEX_URL: where the default index serves a CUDA build (README, "Run it").
python -m pip install -q "torch==2.13.0" ${TORCH_INDEX_URL:+--index-url "$TORCH_INDEX_URL"}
python -m pip install -q -e ".[train,dev,preview]"
python -m pytest "$@"
