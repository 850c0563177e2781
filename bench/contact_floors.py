"""Pins lifted to the clip's resting heights (`codec.contact_floors`) against pins as
sampled, on the same model and seeds: floor penetration, foot skating, jitter and the
paper's metrics, cleanup on as `sample` runs. Models exported before the field existed are
given the floors their clip yields (what training now records), so one model serves both arms.

    python bench/contact_floors.py --model runs/smooth/Joe_Walk-In-Circle/model_w64.onnx \\
        --clip ../shared/motions/Joe_Walk-In-Circle.bvh --results bench/results/contact_floors_walk.json
"""

from __future__ import annotations

import argparse
import json
import tempfile
from collections import Counter
from dataclasses import replace
from pathlib import Path

from sinmdm.eval.balance import eval_preset
from sinmdm.eval.motion_features import evaluate_files
from sinmdm.export.calibrate import clip_resting_heights
from sinmdm.runtime import SamplingOptions, generate, load_model, read_bvh, write_outputs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, required=True)
    parser.add_argument("--clip", type=Path, required=True)
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1000])
    parser.add_argument("--samples", type=int, default=8)
    parser.add_argument("--results", type=Path, default=None)
    args = parser.parse_args()

    model = load_model(args.model)
    reference = read_bvh(args.clip)
    codec = model.codec
    floors = codec.contact_floors if codec.contact_floors is not None else clip_resting_heights(model, reference)
    frames = 2 * round(reference.frames / reference.fps * codec.fps)
    protocol = eval_preset(reference)
    out = {"model": str(args.model), "clip": args.clip.name, "frames": frames, "samples": args.samples,
           "contact_floors_cm": [round(100 * f, 2) for f in floors], "rows": []}
    for arm, arm_floors in (("as sampled", None), ("lifted", floors)):
        arm_model = replace(model, codec=replace(codec, contact_floors=arm_floors))
        for seed in args.seeds:
            result = generate(arm_model, frames, SamplingOptions(count=args.samples, seed=seed))
            with tempfile.TemporaryDirectory() as tmp:
                scores = evaluate_files(args.clip, write_outputs(arm_model, result, Path(tmp), force=True), preset=protocol)
            aggregate = scores["plausibility"]["aggregate"]
            samples = scores["plausibility"]["samples"]
            row = {"pins": arm, "seed": seed, **{k: round(scores[k], 3) for k in ("coverage", "global_diversity", "local_diversity")},
                   **{k: round(float(aggregate[k]), 3) for k in ("foot_skating_cm_s", "foot_bob_cm_s", "penetration_cm",
                                                                 "penetration_share", "jitter_ratio", "root_step_max_ratio")},
                   "implausible": aggregate["implausible"],
                   "verdicts": dict(Counter(s["verdict"].split(" ")[0].rstrip(":") for s in samples))}
            out["rows"].append(row)
            print(row, flush=True)
    if args.results:
        args.results.write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
