"""Where sampled motion shakes: each joint's jerk against the clip's at the model's own
sampling steps and at more steps, and what a light temporal smoothing of the sampled
features (a Gaussian over frames, before decoding) does to jitter and the paper's metrics.
A measurement for the next step on jitter; nothing here is the default sampler.

    python bench/jitter_sources.py --model runs/peer/Joe_Walk-In-Circle/model_w64.onnx \
        --clip ../shared/motions/Joe_Walk-In-Circle.bvh --sigmas 0 1 2
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter1d

from sinmdm.eval.balance import eval_preset
from sinmdm.eval.motion_features import evaluate_files
from sinmdm.runtime import SamplingOptions, generate, load_model, read_bvh, write_outputs
from sinmdm.runtime.animation import animation_from_bvh, global_positions
from sinmdm.runtime.features import resample_animation


def joint_jerk(animation, fps: float) -> np.ndarray:
    """(J,) mean jerk magnitude per joint, at `fps`."""
    positions = global_positions(resample_animation(animation, fps))
    return np.linalg.norm(np.diff(positions, n=3, axis=0), axis=-1).mean(axis=0) * fps**3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, required=True)
    parser.add_argument("--clip", type=Path, required=True)
    parser.add_argument("--sigmas", nargs="+", type=float, default=[0.0, 1.0, 2.0], help="frames; 0: no smoothing")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1000])
    parser.add_argument("--samples", type=int, default=8)
    parser.add_argument("--more-steps", type=int, default=50)
    parser.add_argument("--results", type=Path, default=None)
    args = parser.parse_args()

    model = load_model(args.model)
    reference = read_bvh(args.clip)
    clip = animation_from_bvh(reference)
    fps = model.codec.fps
    frames = 2 * round(clip.frames / clip.fps * fps)
    protocol = eval_preset(reference)
    clip_jerk = joint_jerk(clip, fps)
    names = clip.skeleton.names
    out = {"model": str(args.model), "clip": args.clip.name, "frames": frames, "samples": args.samples,
           "default_steps": model.default_steps, "per_joint": {}, "smoothing": []}
    for steps in (None, args.more_steps):
        result = generate(model, frames, SamplingOptions(count=args.samples, seed=args.seeds[0], steps=steps, cleanup=False))
        ratio = np.mean([joint_jerk(animation_from_bvh(c), fps) for c in result.clips], axis=0) / np.maximum(clip_jerk, 1e-9)
        worst = [(names[j], round(float(ratio[j]), 2)) for j in np.argsort(-ratio)[:6]]
        label = f"{steps or model.default_steps} steps"
        out["per_joint"][label] = {"median_ratio": round(float(np.median(ratio)), 2), "worst": worst}
        print(f"{label}, cleanup off: per-joint jerk ratio median {np.median(ratio):.2f}, worst {worst}", flush=True)
    for sigma in args.sigmas:
        for seed in args.seeds:
            adjust = None if sigma == 0 else (lambda f, s=sigma: gaussian_filter1d(f, s, axis=1, mode="nearest"))
            result = generate(model, frames, SamplingOptions(count=args.samples, seed=seed), adjust=adjust)
            with tempfile.TemporaryDirectory() as tmp:
                scores = evaluate_files(args.clip, write_outputs(model, result, Path(tmp), force=True), preset=protocol)
            aggregate = scores["plausibility"]["aggregate"]
            row = {"sigma_frames": sigma, "seed": seed, **{k: round(scores[k], 3) for k in ("coverage", "global_diversity", "local_diversity")},
                   "jitter_ratio": round(float(np.mean([s["jitter_ratio"] for s in scores["plausibility"]["samples"]])), 2),
                   "foot_skating_cm_s": round(aggregate["foot_skating_cm_s"], 2), "implausible": aggregate["implausible"]}
            out["smoothing"].append(row)
            print(row, flush=True)
    if args.results:
        args.results.write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
