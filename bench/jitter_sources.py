"""Where sampled motion shakes: each joint's jerk against the clip's at the model's own
sampling steps and at more steps, and what the temporal smoothing of the sampled features
(`--smooth`, a Gaussian over frames before decoding; runtime/smoothing.py) does to jitter,
foot skating and the paper's metrics, at each sigma (0: off), cleanup on as `sample` runs.

    python bench/jitter_sources.py --model runs/peer/Joe_Walk-In-Circle/model_w64.onnx \
        --clip ../shared/motions/Joe_Walk-In-Circle.bvh --sigmas 0 1 2
"""

from __future__ import annotations

import argparse
import json
import tempfile
from collections import Counter
from pathlib import Path

import numpy as np

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
    parser.add_argument("--sigmas", nargs="+", type=float, default=[0.0, 1.0], help="frames; 0: no smoothing")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1000])
    parser.add_argument("--samples", type=int, default=8)
    parser.add_argument("--more-steps", type=int, default=50)
    parser.add_argument("--results", type=Path, default=None)
    parser.add_argument("--plot", type=Path, default=None,
                        help="PNG: the most shaken joint's height and speed in seed 0's first sample, off against each sigma")
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
        result = generate(model, frames, SamplingOptions(count=args.samples, seed=args.seeds[0], steps=steps, cleanup=False,
                                                         smooth=0.0))
        ratio = np.mean([joint_jerk(animation_from_bvh(c), fps) for c in result.clips], axis=0) / np.maximum(clip_jerk, 1e-9)
        worst = [(names[j], round(float(ratio[j]), 2)) for j in np.argsort(-ratio)[:6]]
        label = f"{steps or model.default_steps} steps"
        out["per_joint"][label] = {"median_ratio": round(float(np.median(ratio)), 2), "worst": worst}
        print(f"{label}, cleanup off: per-joint jerk ratio median {np.median(ratio):.2f}, worst {worst}", flush=True)
    for sigma in args.sigmas:
        for seed in args.seeds:
            result = generate(model, frames, SamplingOptions(count=args.samples, seed=seed, smooth=sigma))
            with tempfile.TemporaryDirectory() as tmp:
                scores = evaluate_files(args.clip, write_outputs(model, result, Path(tmp), force=True), preset=protocol)
            aggregate = scores["plausibility"]["aggregate"]
            row = {"sigma_frames": sigma, "seed": seed, **{k: round(scores[k], 3) for k in ("coverage", "global_diversity", "local_diversity")},
                   "jitter_ratio": round(float(np.mean([s["jitter_ratio"] for s in scores["plausibility"]["samples"]])), 2),
                   **{k: round(aggregate[k], 3) for k in ("foot_skating_cm_s", "penetration_cm", "penetration_share",
                                                          "root_step_max_ratio", "backward_share")},
                   "implausible": aggregate["implausible"],
                   "verdicts": dict(Counter(s["verdict"].split(" ")[0].rstrip(":") for s in scores["plausibility"]["samples"]))}
            out["smoothing"].append(row)
            print(row, flush=True)
    if args.results:
        args.results.write_text(json.dumps(out, indent=2) + "\n")
    if args.plot:
        plot_joint(model, clip, names.index(out["per_joint"][f"{model.default_steps} steps"]["worst"][0][0]), args, frames)


def plot_joint(model, clip, joint: int, args, frames: int) -> None:
    """The joint's height and speed over 3 s of one sample (seed 0), at each sigma, and the clip's."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fps = model.codec.fps
    span = slice(0, min(frames, int(3 * fps)))
    up = model.codec.up_axis
    fig, (height, speed) = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True)
    own = global_positions(resample_animation(clip, fps))[span, joint]
    for sigma in args.sigmas:
        sample = generate(model, frames, SamplingOptions(seed=args.seeds[0], smooth=sigma)).clips[0]
        p = global_positions(resample_animation(animation_from_bvh(sample), fps))[span, joint]
        label = "smoothing off" if sigma == 0 else f"smoothing {sigma:g} frame"
        height.plot(p[:, up], label=label)
        speed.plot(np.linalg.norm(np.diff(p, axis=0), axis=-1) * fps, label=label)
    speed.plot(np.linalg.norm(np.diff(own, axis=0), axis=-1) * fps, color="0.6", lw=1, label="the clip (its first 3 s)")
    name = clip.skeleton.names[joint].split(":")[-1]
    height.set_ylabel(f"{name} height (file units)")
    speed.set_ylabel(f"{name} speed (units/s)")
    speed.set_xlabel(f"frame at {fps:g} fps")
    height.legend(fontsize=8)
    speed.legend(fontsize=8)
    fig.suptitle(f"{args.clip.stem}: the most shaken joint, one sample (seed {args.seeds[0]}, cleanup on)")
    fig.tight_layout()
    fig.savefig(args.plot, dpi=90)


if __name__ == "__main__":
    main()
