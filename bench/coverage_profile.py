"""Where along the clip coverage is lost: for each stretch of the clip's 30-frame windows, the
share of samples that reproduce them (the paper's coverage, per window instead of averaged).

    python bench/coverage_profile.py --clip ../shared/motions/Joe_Baseball-Milling-Idle.bvh \
        --samples runs/A/CLIP/samples_default runs/B/CLIP/samples_default --bins 10

Each folder of BVH samples gives one column; the clip is scored under the protocol the watch uses
(`eval_preset`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from sinmdm.eval import metrics  # noqa: E402
from sinmdm.eval.balance import eval_preset  # noqa: E402
from sinmdm.eval.motion_features import eval_features, protocol_for  # noqa: E402
from sinmdm.runtime.bvh import read_bvh  # noqa: E402


def profile(clip: Path, folder: Path) -> np.ndarray:
    """(windows,) share of the folder's samples covering each window of the clip."""
    reference = read_bvh(clip)
    protocol = protocol_for(reference, eval_preset(reference))
    features = eval_features(reference, protocol)
    hits = [metrics.covered_windows(features, eval_features(read_bvh(p), protocol)) for p in sorted(folder.glob("*.bvh"))]
    return np.mean(hits, axis=0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clip", type=Path, required=True)
    parser.add_argument("--samples", type=Path, nargs="+", required=True)
    parser.add_argument("--bins", type=int, default=10)
    args = parser.parse_args()
    shares = [profile(args.clip, folder) for folder in args.samples]
    count = len(shares[0])
    print("windows | " + " | ".join(str(f) for f in args.samples))
    print("coverage | " + " | ".join(f"{100 * s.mean():.1f}" for s in shares))
    for b in range(args.bins):
        start, stop = b * count // args.bins, (b + 1) * count // args.bins
        print(f"{start}-{stop - 1} | " + " | ".join(f"{100 * s[start:stop].mean():.1f}" for s in shares))


if __name__ == "__main__":
    main()
