"""What a clip allows: the paper's metrics of one half of the clip scored against the
other half (both ways, mean). A clip whose own halves are this close (global
diversity far below 1.3) cannot give samples that are both faithful and that varied.

    python bench/clip_allows.py --results bench/results/clip_allows.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.quality import MOTIONS, eval_protocol  # noqa: E402

CLIPS = ("Joe_Walk-In-Circle.bvh", "Joe_Baseball-Milling-Idle.bvh", "Crabnew_Crab-dance-long.bvh",
         "Elephant_idle1.bvh", "Xia_normal.bvh", "Xia_proud.bvh")


def halves(name: str) -> dict:
    from sinmdm.eval import metrics
    from sinmdm.eval.motion_features import eval_features, protocol_for
    from sinmdm.runtime import read_bvh

    clip = read_bvh(MOTIONS / name)
    protocol = protocol_for(clip, eval_protocol(name))
    features = eval_features(clip, protocol)
    half = len(features) // 2
    a, b = features[:half], features[half:]
    scores = [metrics.evaluate(ref, [sample]) for ref, sample in ((a, b), (b, a))]
    return {"clip": name, "frames": len(features), "eval_preset": protocol.preset,
            **{k: sum(s[k] for s in scores) / 2 for k in ("coverage", "global_diversity", "local_diversity")}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=Path, default=ROOT / "bench" / "results" / "clip_allows.json")
    args = parser.parse_args()
    rows = [halves(name) for name in CLIPS]
    for row in rows:
        print(json.dumps(row))
    args.results.write_text(json.dumps(rows, indent=2) + "\n")


if __name__ == "__main__":
    main()
