"""The foot cleanup as `sample` runs it, against no cleanup, on trained models: jitter (the
verdict's ratio to the clip's jerk), foot skating, bobbing and lift, knees locked straight, the paper's metrics
and the plausibility verdicts. Run it under two checkouts to compare two cleanups on the
same samples (only `sinmdm` differs; the seeds and the model's own sampling settings are
the same):

    python bench/cleanup_ab.py --label eased --results bench/results/cleanup_ab_2026-12-07.json \\
        --model runs/default_1207/Xia_proud/model_w64.onnx --clip ../shared/motions/Xia_proud.bvh
    PYTHONPATH=/path/to/older/checkout python bench/cleanup_ab.py --label fade ...
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
from sinmdm.runtime.cleanup import find_legs

STRAIGHT_DEG = 179.0


def two_bone_legs(animation, codec) -> list:
    """The legs the cleanup solves with a hip and a knee (not a many-jointed chain)."""
    return [leg for leg in find_legs(animation, codec, global_positions(animation)) if leg.hip is not None and not leg.chain]


def knee_angles(animation, legs) -> np.ndarray:
    """(T, legs) the angle at each two-bone leg's knee, degrees (180 = straight)."""
    p = global_positions(animation)
    out = []
    for leg in legs:
        u, v = p[:, leg.hip] - p[:, leg.knee], p[:, leg.effector] - p[:, leg.knee]
        cos = np.sum(u * v, axis=-1) / np.maximum(np.linalg.norm(u, axis=-1) * np.linalg.norm(v, axis=-1), 1e-12)
        out.append(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
    return np.stack(out, axis=1) if out else np.zeros((len(p), 0))


def score(model, clip_path: Path, protocol: str, cleanup: bool, samples: int, seeds: list[int], legs) -> dict:
    clip = animation_from_bvh(read_bvh(clip_path))
    frames = 2 * round(clip.frames / clip.fps * model.codec.fps)
    rows, verdicts, straight, steps = [], Counter(), [], []
    for seed in seeds:
        result = generate(model, frames, SamplingOptions(count=samples, seed=seed, cleanup=cleanup))
        with tempfile.TemporaryDirectory() as tmp:
            scores = evaluate_files(clip_path, write_outputs(model, result, Path(tmp), force=True), preset=protocol)
        per = scores["plausibility"]["samples"]
        rows.append({"seed": seed, **{k: scores[k] for k in ("coverage", "global_diversity", "local_diversity")},
                     "jitter_ratio": float(np.mean([s["jitter_ratio"] for s in per])),
                     **{k: scores["plausibility"]["aggregate"][k] for k in (
                         "foot_skating_cm_s", "clip_foot_skating_cm_s", "foot_bob_cm_s", "clip_foot_bob_cm_s",
                         "foot_lift_cm", "clip_foot_lift_cm")}})
        verdicts.update(s["verdict"].split(" ")[0].rstrip(":") for s in per)
        for sample in result.clips:
            angles = knee_angles(animation_from_bvh(sample), legs)
            straight.append(float((angles > STRAIGHT_DEG).any(axis=1).mean()) if angles.size else 0.0)
            steps.append(float(np.abs(np.diff(angles, axis=0)).max()) if len(angles) > 1 and angles.size else 0.0)
    mean = {k: float(np.mean([r[k] for r in rows])) for k in rows[0] if k != "seed"}
    return {**mean, "per_seed": rows, "verdicts": dict(verdicts), "plausible": verdicts.get("plausible", 0),
            "samples": samples * len(seeds), "knee_straight_share": float(np.mean(straight)),
            "knee_largest_step_deg": float(np.max(steps)) if steps else 0.0}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, required=True)
    parser.add_argument("--clip", type=Path, required=True)
    parser.add_argument("--label", required=True, help="which cleanup this checkout has")
    parser.add_argument("--samples", type=int, default=10, help="per seed")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1000])
    parser.add_argument("--off", action="store_true", help="also score the samples without cleanup")
    parser.add_argument("--results", type=Path, default=None, help="append the rows to this JSON list")
    args = parser.parse_args()

    model = load_model(args.model)
    reference = read_bvh(args.clip)
    protocol = eval_preset(reference)
    clip = animation_from_bvh(reference)
    legs = two_bone_legs(clip, model.codec)
    own = knee_angles(clip, legs)
    rows = []
    for cleanup in ([False] if args.off else []) + [True]:
        row = {"model": str(args.model), "clip": args.clip.name, "protocol": protocol,
               "cleanup": args.label if cleanup else "off", "clip_knee_max_deg": float(own.max()) if own.size else None,
               **score(model, args.clip, protocol, cleanup, args.samples, args.seeds, legs)}
        rows.append(row)
        print(json.dumps({k: (round(v, 3) if isinstance(v, float) else v) for k, v in row.items() if k != "per_seed"}), flush=True)
    if args.results:
        existing = json.loads(args.results.read_text()) if args.results.exists() else []
        args.results.write_text(json.dumps(existing + rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
