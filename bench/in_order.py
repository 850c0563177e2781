"""How much of a clip a sample can cover when it follows the clip in order only for
stretches of a given length, against how long the samples of a model really follow it.

The paper's coverage is per sample: a sample of twice the clip's length must pass close to
nearly every 30-frame window of the clip. A clip that repeats itself (a walk cycle) offers
each window many times; a clip that never repeats (the crab's dance: its halves share no
window) has to be replayed nearly in order. Two measurements:

- *copied stretches*: samples made of exact copies of the clip's frames, in stretches of L
  frames from random places (20 samples of twice the clip, two seeds), scored by the paper's
  coverage: what a flawless model that keeps the clip's order for L frames at a time would get
  (L = the whole clip: the clip replayed from its start, 100 %);
- *in-order run length* of real samples: each sample frame's nearest clip frame (best 15-frame
  window), and the frame-weighted mean length of runs in which that match advances by 0-2
  frames per frame.

    python bench/in_order.py --clip Crabnew_Crab-dance-long.bvh --samples-dir runs/.../samples_default
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.quality import MOTIONS, eval_protocol  # noqa: E402

STRETCHES = (32, 64, 96, 128, 192, 256)
MATCH_WINDOW = 15
SEEDS = (0, 1)


def copied_stretches(reference: np.ndarray, length: int, samples: int = 20, seed: int = 0) -> float:
    """Coverage (%) of `samples` motions of twice the clip made of its frames in stretches of `length`."""
    from sinmdm.eval import metrics

    rng = np.random.default_rng(seed)
    frames = 2 * len(reference)
    motions = []
    for _ in range(samples):
        starts = rng.integers(0, len(reference) - length + 1, size=-(-frames // length))
        motions.append(np.concatenate([reference[s:s + length] for s in starts])[:frames])
    return round(metrics.coverage_many(reference, motions), 1)


def in_order_runs(reference: np.ndarray, sample: np.ndarray) -> np.ndarray:
    """Lengths of the runs in which the sample's nearest clip frame advances by 0-2 per frame."""
    from sinmdm.eval import metrics

    costs = metrics._window_sums(metrics.frame_distances(sample, reference), MATCH_WINDOW)
    match = costs.argmin(axis=1)
    steps = np.diff(match)
    breaks = np.flatnonzero((steps < 0) | (steps > 2))
    edges = np.concatenate([[0], breaks + 1, [len(match)]])
    return np.diff(edges)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clip", required=True)
    parser.add_argument("--samples-dir", type=Path, action="append", default=[])
    parser.add_argument("--results", type=Path)
    args = parser.parse_args()
    from sinmdm.eval.motion_features import eval_features, protocol_for
    from sinmdm.runtime import read_bvh

    clip = read_bvh(MOTIONS / args.clip)
    protocol = protocol_for(clip, eval_protocol(args.clip))
    reference = eval_features(clip, protocol)
    result = {"clip": args.clip, "frames": len(reference), "copied": [], "samples": []}
    for length in (*STRETCHES, len(reference)):
        if length > len(reference):
            continue
        seeds = [copied_stretches(reference, length, seed=seed) for seed in SEEDS]
        result["copied"].append({"stretch": length, "coverage_per_seed": seeds, "coverage": round(float(np.mean(seeds)), 1)})
        print(json.dumps(result["copied"][-1]), flush=True)
    for folder in args.samples_dir:
        runs = [in_order_runs(reference, eval_features(read_bvh(f), protocol)) for f in sorted(folder.glob("*.bvh"))]
        lengths = np.concatenate(runs)
        row = {"samples": str(folder), "count": len(runs),
               "in_order_run_frames": round(float((lengths ** 2).sum() / lengths.sum()), 1)}
        result["samples"].append(row)
        print(json.dumps(row), flush=True)
    if args.results:  # one entry per clip
        rows = json.loads(args.results.read_text()) if args.results.exists() else []
        rows = [r for r in rows if r["clip"] != args.clip] + [result]
        args.results.write_text(json.dumps(rows, indent=2) + "\n")


if __name__ == "__main__":
    main()
