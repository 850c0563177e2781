"""What a clip's coverage misses, and by how much: per folder of samples, the paper's coverage; the
same with the contact labels left out (rotations only); the contact labels' share of the squared
cost of each clip window's best match; how often a sample's label disagrees with its match (the
sample's joint moving where the clip's is still, and the reverse); and the coverage at looser
thresholds, to show how far the missed windows lie from the paper's 2.0.

    python bench/coverage_margin.py --clip ../shared/motions/Crabnew_Crab-dance-long.bvh \
        --samples runs/A/Crabnew_Crab-dance-long/samples_default [--results bench/results/X.json]

The clip is scored under the protocol the watch uses (`eval_preset`). Diagnostic only: the
project's scores stay the paper's.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from sinmdm.eval import metrics  # noqa: E402
from sinmdm.eval.balance import eval_preset  # noqa: E402
from sinmdm.eval.motion_features import eval_features, protocol_for, resolve_joints  # noqa: E402
from sinmdm.runtime.bvh import read_bvh  # noqa: E402

WINDOW = metrics.COVERAGE_WINDOW
LOOSER = (1.125, 1.25, 1.5)


def best_matches(reference: np.ndarray, sample: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per scored reference window: the start of its best sample window and that match's mean cost."""
    # The paper scores reference starts 0 .. T - 31 (metrics._covered_from_distances).
    sums = metrics._window_sums(metrics.frame_distances(sample, reference), WINDOW)[:, : len(reference) - WINDOW]
    best = sums.argmin(axis=0)
    return best, sums[best, np.arange(sums.shape[1])] / WINDOW


def margin(clip: Path, folder: Path) -> dict:
    reference = read_bvh(clip)
    preset = eval_preset(reference)
    protocol = protocol_for(reference, preset)
    rotations = 6 * len(resolve_joints(reference.skeleton, protocol.joints, protocol.match))
    ref = eval_features(reference, protocol)
    rows = {"paper": [], "rotations only": [], **{f"threshold x{f:g}": [] for f in LOOSER}}
    contact_share, moving, still, labels = [], [], [], []
    for path in sorted(folder.glob("*.bvh")):
        sample = eval_features(read_bvh(path), protocol)
        best, cost = best_matches(ref, sample)
        rows["paper"].append(100 * np.mean(cost < metrics.COVERAGE_THRESHOLD))
        for f in LOOSER:
            rows[f"threshold x{f:g}"].append(100 * np.mean(cost < f * metrics.COVERAGE_THRESHOLD))
        rows["rotations only"].append(metrics.coverage(ref[:, :rotations], sample[:, :rotations]))
        if ref.shape[1] > rotations:
            frames = best[:, None] + np.arange(WINDOW)  # (windows, 30) sample frames matched
            matched = sample[frames]  # (windows, 30, F)
            clip_frames = ref[np.arange(len(best))[:, None] + np.arange(WINDOW)]
            squared = (matched - clip_frames) ** 2
            contact_share.append(squared[..., rotations:].sum() / max(squared.sum(), 1e-12))
            s, c = matched[..., rotations:], clip_frames[..., rotations:]
            moving.append(np.mean((s < 0.5) & (c > 0.5)))
            still.append(np.mean((s > 0.5) & (c < 0.5)))
            labels.append(np.mean(sample[:, rotations:]))
    result = {"clip": clip.name, "samples": str(folder), "count": len(rows["paper"]), "eval_preset": preset,
              "coverage": {k: round(float(np.mean(v)), 1) for k, v in rows.items()}}
    if contact_share:
        result["contacts"] = {
            "columns": int(ref.shape[1] - rotations),
            "share_of_matched_cost": round(float(np.mean(contact_share)), 3),
            "moving_where_clip_still": round(float(np.mean(moving)), 3),
            "still_where_clip_moving": round(float(np.mean(still)), 3),
            "sample_still_share": round(float(np.mean(labels)), 3),
            "clip_still_share": round(float(ref[:, rotations:].mean()), 3),
        }
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clip", type=Path, required=True)
    parser.add_argument("--samples", type=Path, nargs="+", required=True)
    parser.add_argument("--results", type=Path, default=None, help="append the rows to this JSON list")
    args = parser.parse_args()
    results = [margin(args.clip, folder) for folder in args.samples]
    for row in results:
        print(json.dumps(row), flush=True)
    if args.results:
        previous = json.loads(args.results.read_text()) if args.results.exists() else []
        args.results.parent.mkdir(parents=True, exist_ok=True)
        args.results.write_text(json.dumps(previous + results, indent=2) + "\n")


if __name__ == "__main__":
    main()
