#!/usr/bin/env bash
# Rebuild the bundled demo model from the bundled example clip (about 5 minutes on 2 CPU cores).
set -euo pipefail
cd "$(dirname "$0")/.."
RUN="${1:-runs/demo}"
python scripts/make_demo_clip.py
sinmdm train sinmdm/runtime/demo/stomper.bvh --out "$RUN" --preset cpu --width 128 --steps 1500 --seed 0
sinmdm export "$RUN" --out sinmdm/runtime/demo/stomper.onnx --force
ls -la sinmdm/runtime/demo/
