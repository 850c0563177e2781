"""How fast the knees bend, frame to frame, in samples with and without the foot cleanup,
beside the clip's own: where a pinned foot lands away from where the model put it, the
cleanup bends the knee in a hurry (an animator sees a knee snap). Run it under two
checkouts to compare two cleanups on the same samples:

    python bench/knee_steps.py --model runs/watched/Joe_Walk-In-Circle/model_w64.onnx \\
        --clip ../shared/motions/Joe_Walk-In-Circle.bvh --label eased
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

# Appended, not prepended: a PYTHONPATH pointing at another checkout's sinmdm still wins.
sys.path.append(str(Path(__file__).resolve().parents[1]))

from bench.cleanup_ab import knee_angles, two_bone_legs  # noqa: E402
from sinmdm.runtime import SamplingOptions, generate, load_model, read_bvh  # noqa: E402
from sinmdm.runtime.animation import animation_from_bvh  # noqa: E402
from sinmdm.runtime.features import resample_animation  # noqa: E402


def steps(animation, codec) -> np.ndarray:
    """(T-1, legs) each two-bone knee's angle change per frame, degrees."""
    return np.abs(np.diff(knee_angles(animation, two_bone_legs(animation, codec)), axis=0))


def summary(values: list[np.ndarray]) -> dict:
    flat = np.concatenate([v.ravel() for v in values])
    return {"max_deg": float(flat.max()), "p99_deg": float(np.percentile(flat, 99)),
            "per_sample_max_deg": [round(float(v.max()), 1) for v in values]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, required=True)
    parser.add_argument("--clip", type=Path, required=True)
    parser.add_argument("--label", required=True, help="which cleanup this checkout has")
    parser.add_argument("--samples", type=int, default=6)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    model = load_model(args.model)
    clip = animation_from_bvh(read_bvh(args.clip))
    frames = 2 * round(clip.frames / clip.fps * model.codec.fps)
    row = {"model": str(args.model), "clip": args.clip.name,
           "clip_steps": summary([steps(resample_animation(clip, model.codec.fps), model.codec)])}
    for cleanup, label in ((False, "off"), (True, args.label)):
        result = generate(model, frames, SamplingOptions(count=args.samples, seed=args.seed, cleanup=cleanup))
        row[label] = summary([steps(animation_from_bvh(s), model.codec) for s in result.clips])
    print(json.dumps(row))


if __name__ == "__main__":
    main()
