"""Loop seams: how far `sample --loop` jumps at the wrap, against the training clip.

    python bench/loop_seam.py                       # the bundled demo model, 8 samples
    python bench/loop_seam.py --model runs/x/model_w64.onnx --clip clip.bvh --samples 8

The measurement, per pair of consecutive frames (a, b): the mean over joints of
the distance between their world positions (global_positions of the decoded BVH,
file units). At the wrap the pair is (frame T-1, frame T), where frame T is frame 0
of the next cycle: frame 0 with the trajectory joint moved by the cycle's root
displacement (`cycle_displacement`: the sum of the root's per-frame horizontal
velocities, frame 0's being the step across the wrap), so the root motion a game
engine applies per cycle is not counted as a jump. The velocity seam is the same
mean of the second difference |p[a-1] - 2 p[a] + p[a+1]|, the larger of the two
centred on T-1 and on T. Both are compared with the medians of the same quantities
over the training clip (at the model's frame rate), and the second difference also with
the sample's own median away from the wrap. Samples without --loop, with
their displacement computed the same way, show what an ordinary end-start jump is.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from sinmdm.runtime import SamplingOptions, generate, load_model, read_bvh
from sinmdm.runtime.animation import Animation, animation_from_bvh, global_positions
from sinmdm.runtime.model import DEMO_MODEL
from sinmdm.runtime.sampler import cycle_displacement

DEMO_CLIP = DEMO_MODEL.with_name("stomper.bvh")


def _mean_norm(d: np.ndarray) -> np.ndarray:
    """(..., J, 3) -> (...): mean over joints of the vector lengths."""
    return np.linalg.norm(d, axis=-1).mean(axis=-1)


def clip_medians(codec, clip, source_fps: float | None = None) -> dict:
    """Median per-frame change and second difference of a clip, at the codec's frame rate (file units)."""
    bvh = read_bvh(clip) if isinstance(clip, (str, Path)) else clip
    positions = global_positions(codec.animation(bvh, source_fps))
    return {
        "step": float(np.median(_mean_norm(np.diff(positions, axis=0)))),
        "second": float(np.median(_mean_norm(np.diff(positions, n=2, axis=0)))),
    }


def next_cycle(codec, animation: Animation, displacement_m: np.ndarray, frames: int = 2) -> Animation:
    """The first `frames` frames of the next cycle: the trajectory joint moved by the
    per-cycle displacement (metres, along codec.horizontal_axes in its parent's frame)."""
    translations = animation.translations[:frames].copy()
    if codec.trajectory_joint is not None:
        for axis, metres in zip(codec.horizontal_axes, displacement_m):
            translations[:, codec.trajectory_joint, axis] += metres / codec.scale
    return Animation(animation.skeleton, animation.rotations[:frames], translations, animation.fps)


def seam(codec, clip, displacement_m: np.ndarray) -> dict:
    """Position jump and second difference at the wrap of one decoded clip (file units),
    and the same two statistics at every pair of consecutive frames inside the sample:
    the wrap is a seam only if it stands out from the sample's own frames."""
    animation = animation_from_bvh(clip)
    ahead = next_cycle(codec, animation, np.asarray(displacement_m, dtype=np.float64))
    tail = Animation(animation.skeleton, animation.rotations[-2:], animation.translations[-2:], animation.fps)
    p = np.concatenate([global_positions(tail), global_positions(ahead)])  # frames T-2, T-1, T, T+1
    second = max(_mean_norm(p[0] - 2 * p[1] + p[2]), _mean_norm(p[1] - 2 * p[2] + p[3]))
    inside = global_positions(animation)
    own_steps = _mean_norm(np.diff(inside, axis=0))[1:-1]  # pairs (a-1, a) with a second difference on each side
    centred = _mean_norm(np.diff(inside, n=2, axis=0))
    own_seconds = np.maximum(centred[:-1], centred[1:])  # the wrap's statistic at every inner pair
    step = float(_mean_norm(p[2] - p[1]))
    return {"step": step, "second": float(second),
            "own_step": float(np.median(own_steps)), "own_second": float(np.median(own_seconds)),
            # share of the sample's own frame pairs that change less than the wrap does
            "step_rank": float(np.mean(own_steps < step)), "second_rank": float(np.mean(own_seconds < second))}


def measure(model, clip, samples: int = 8, frames: int | None = None, seed: int = 0, steps: int | None = 50,
            hop: int | None = None, source_fps: float | None = None, cleanup: bool | None = None) -> dict:
    """Seams of `samples` loops and as many ordinary samples (same seeds), against the clip's medians."""
    frames = frames or int(round(4 * model.codec.fps))
    reference = clip_medians(model.codec, clip, source_fps)
    extra = {} if cleanup is None else {"cleanup": cleanup}  # None: generate()'s default
    report = {"frames": frames, "samples": samples, "seed": seed, "steps": steps, "units": "file units", **extra,
              "metres_per_unit": model.codec.scale, "clip_median": reference}
    for name, loop in (("loop", True), ("no_loop", False)):
        result = generate(model, frames, SamplingOptions(count=samples, seed=seed, steps=steps, hop=hop, **extra), loop=loop)
        shifts = cycle_displacement(model.codec, result.features)
        rows = [seam(model.codec, c, d) for c, d in zip(result.clips, shifts)]
        steps_, seconds = np.array([r["step"] for r in rows]), np.array([r["second"] for r in rows])
        report[name] = {
            "step": steps_.tolist(), "second": seconds.tolist(),
            "step_over_clip_median": {"median": float(np.median(steps_) / reference["step"]),
                                      "max": float(steps_.max() / reference["step"])},
            "second_over_clip_median": {"median": float(np.median(seconds) / reference["second"]),
                                        "max": float(seconds.max() / reference["second"])},
            "step_over_own_median": float(np.median(steps_ / np.array([r["own_step"] for r in rows]))),
            "second_over_own_median": float(np.median(seconds / np.array([r["own_second"] for r in rows]))),
            "step_rank": float(np.median([r["step_rank"] for r in rows])),
            "second_rank": float(np.median([r["second_rank"] for r in rows])),
            "displacement_m": shifts.tolist(),
        }
    return report


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, nargs="+", default=None, help="model .onnx file(s) (default: the demo)")
    parser.add_argument("--clip", type=Path, default=None, help="the model's training clip (needed with --model)")
    parser.add_argument("--source-fps", type=float, default=None, help="the clip's real frame rate if its header is wrong")
    parser.add_argument("--samples", type=int, default=8)
    parser.add_argument("--seconds", type=float, default=4.0)
    parser.add_argument("--steps", type=int, default=50)
    parser.add_argument("--hop", type=int, default=None)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-cleanup", action="store_true", help="decode without the foot-contact cleanup")
    parser.add_argument("--json", type=Path, default=None, help="also write the full report here")
    args = parser.parse_args()
    if args.model and not args.clip:
        parser.error("--model needs --clip (the clip it was trained on)")
    model = load_model(args.model)
    clip = args.clip or DEMO_CLIP
    report = measure(model, clip, args.samples, int(round(args.seconds * model.codec.fps)), args.seed, args.steps,
                     args.hop, args.source_fps, False if args.no_cleanup else None)
    report["model"] = [str(p) for p in (args.model or [DEMO_MODEL])]
    report["clip"] = str(clip)
    ref = report["clip_median"]
    print(f"{Path(report['model'][0]).name} on {Path(clip).name}: {args.samples} samples x {report['frames']} frames, "
          f"{args.steps} steps{', no cleanup' if args.no_cleanup else ''}")
    print(f"clip median: step {ref['step']:.4g}, second difference {ref['second']:.4g} (file units)")
    for name in ("loop", "no_loop"):
        r = report[name]
        print(f"{name:8s} wrap step: median {np.median(r['step']):.4g} (x{r['step_over_clip_median']['median']:.2f} "
              f"of the clip median, max x{r['step_over_clip_median']['max']:.2f}); "
              f"second difference: median {np.median(r['second']):.4g} "
              f"(x{r['second_over_clip_median']['median']:.2f}, max x{r['second_over_clip_median']['max']:.2f}; "
              f"x{r['second_over_own_median']:.2f} of the sample's own)")
        print(f"{'':8s} against the sample's own frame pairs: step x{r['step_over_own_median']:.2f}, second difference "
              f"x{r['second_over_own_median']:.2f} of their medians; the wrap changes more than "
              f"{100 * r['step_rank']:.0f} % / {100 * r['second_rank']:.0f} % of them (median sample)")
    if args.json:
        args.json.write_text(json.dumps(report, indent=2) + "\n")


if __name__ == "__main__":
    main()
