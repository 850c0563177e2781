"""Where a model loses its clip's turning: samples of one window (no joins) and of twice the
clip's length at several hops (windows joined), scored with the plausibility metrics'
turning (mean heading change per second, distance to the clip's) and fastest turn.

    python bench/turning.py MODEL.onnx CLIP.bvh --tag walk-world --results bench/results/turning_2026-12-06.json

A model that does not turn within one window has not learnt the turn; one that turns within a
window and spins at the joins loses it where windows of different headings are blended.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", type=Path)
    parser.add_argument("clip", type=Path)
    parser.add_argument("--tag", required=True)
    parser.add_argument("--results", type=Path, required=True)
    parser.add_argument("--samples", type=int, default=8)
    parser.add_argument("--steps", type=int, default=20)
    args = parser.parse_args()

    from sinmdm.eval.plausibility import plausibility
    from sinmdm.runtime import SamplingOptions, generate, load_model, read_bvh

    model, reference = load_model(args.model), read_bvh(args.clip)
    window = model.trained_window
    length = 2 * round(reference.frames / reference.fps * model.codec.fps)
    rows = []
    for frames, hop in ((window, None), (length, window // 4), (length, window // 2), (length, 3 * window // 4), (length, window)):
        result = generate(model, frames, SamplingOptions(count=args.samples, seed=0, steps=args.steps, hop=hop, cleanup=False))
        scores = plausibility(reference, result.clips)
        a = scores["aggregate"]
        rows.append({"frames": frames, "hop": hop, "turning_deg_s": a["turning_deg_s"],
                     "clip_turning_deg_s": a["clip_turning_deg_s"], "turning_distance_deg_s": a["turning_distance_deg_s"],
                     "fastest_turn_deg_s": [round(s["fastest_turn_deg_s"]) for s in scores["samples"]],
                     "clip_fastest_turn_deg_s": a["clip_fastest_turn_deg_s"],
                     "verdicts": [s["verdict"] for s in scores["samples"]]})
        print(json.dumps(rows[-1]), flush=True)
    results = json.loads(args.results.read_text()) if args.results.exists() else []
    results = [r for r in results if r["tag"] != args.tag] + [
        {"tag": args.tag, "model": str(args.model), "clip": args.clip.name, "window": window, "samples": args.samples,
         "steps": args.steps, "rows": rows, "date": time.strftime("%Y-%m-%d")}]
    args.results.parent.mkdir(parents=True, exist_ok=True)
    args.results.write_text(json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    main()
