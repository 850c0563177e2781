"""Do the model's feet stop where its own contact labels say they are planted? Raw samples (no
cleanup, no smoothing) against the clip: the contact joints' horizontal speed over 5 frames on
frames whose label is on for all 5, and the share of all frames a contact joint moves slower than
10 cm/s.

    python bench/stance_drift.py --model runs/X/CLIP/model_w64.onnx --clip ../shared/motions/CLIP.bvh

A model whose labels switch on at the clip's rate while its feet keep moving glides: the
cleanup can pin only runs the feet nearly stop in (BENCHMARKS.md, "Feet the model does not stop").
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from sinmdm.runtime.animation import global_positions  # noqa: E402
from sinmdm.runtime.bvh import read_bvh  # noqa: E402
from sinmdm.runtime.model import load_model  # noqa: E402
from sinmdm.runtime.options import SamplingOptions  # noqa: E402
from sinmdm.runtime.sampler import sample_features  # noqa: E402

SPAN = 5  # frames over which a speed is measured: longer than the shaking, shorter than a step
STILL_CM_S = 10.0


def speeds(codec, features: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(speeds cm/s over SPAN frames (T - SPAN, C), labelled on throughout (T - SPAN, C))."""
    feet = global_positions(codec.decode(features))[:, list(codec.contact_joints)][:, :, list(codec.horizontal_axes)]
    speed = np.linalg.norm(feet[SPAN:] - feet[:-SPAN], axis=-1) * codec.scale * 100 * codec.fps / SPAN
    labelled = features[:, codec.layout.indices(("contact",))] > 0.5
    throughout = np.stack([labelled[i : len(labelled) - SPAN + i] for i in range(SPAN + 1)]).all(axis=0)
    return speed, throughout


def summary(codec, motions: list[np.ndarray]) -> dict:
    pairs = [speeds(codec, m) for m in motions]
    speed = np.concatenate([s.ravel() for s, _ in pairs])
    labelled = np.concatenate([s[on] for s, on in pairs])
    return {"labelled_median_cm_s": round(float(np.median(labelled)), 1),
            "labelled_p75_cm_s": round(float(np.percentile(labelled, 75)), 1),
            "still_share": round(float(np.mean(speed < STILL_CM_S)), 3),
            "labels_on": round(float(np.mean([np.mean(m[:, codec.layout.indices(("contact",))] > 0.5) for m in motions])), 3)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, required=True)
    parser.add_argument("--clip", type=Path, required=True)
    parser.add_argument("--samples", type=int, default=8)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    model = load_model(args.model, threads=1)
    codec = model.codec
    reference = codec.encode(codec.animation(read_bvh(args.clip)))
    frames = 2 * len(reference)
    options = SamplingOptions(count=args.samples, seed=args.seed, smooth=0.0).resolve(model, frames, False)
    sampled = sample_features(model, frames, options)
    print(json.dumps({"model": str(args.model), "clip": summary(codec, [reference]),
                      "samples": summary(codec, list(sampled)), "steps": options.steps, "hop": options.hop}))


if __name__ == "__main__":
    main()
