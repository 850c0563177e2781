"""Which check a lift-aware keep would take instead, replayed on the checks watched runs logged
(`bench/watched.py` results): where the best-balanced check's feet shuffle (lift under the
verdict's LIFT_RATIO of the clip's), the best-balanced check whose feet do not, if its balance is
within SLACK of the best. No training: it reads the logged scores (a replay of the choice only;
what the other check's weights sample like needs a run that keeps them).

    python bench/lift_tiebreak.py bench/results/watched_lower_a-2026-12-08.json ...
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from sinmdm.eval.balance import keepable
from sinmdm.eval.plausibility import LIFT_RATIO


def lift_aware(checks: list[dict], slack: float) -> tuple[dict, dict]:
    """(the best-balanced check, the one a lift-aware keep would take)."""
    kept = [c for c in checks if keepable(c)]
    best = max(kept, key=lambda c: c["balance"])
    if best.get("foot_lift_ratio", LIFT_RATIO) >= LIFT_RATIO:
        return best, best
    lifting = [c for c in kept if c.get("foot_lift_ratio", 0.0) >= LIFT_RATIO and c["balance"] >= best["balance"] - slack]
    return best, max(lifting, key=lambda c: c["balance"]) if lifting else best


def describe(c: dict) -> str:
    return (f"step {c['step']}: {c['coverage']:.1f} / {c['global_diversity']:.2f}, lift {c.get('foot_lift_ratio', float('nan')):.2f}x, "
            f"balance {c['balance']:.3f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", type=Path, nargs="+")
    parser.add_argument("--slack", type=float, nargs="+", default=[0.03, 0.05])
    args = parser.parse_args()
    print("| run | kept (best balance) | " + " | ".join(f"lift-aware, slack {s}" for s in args.slack) + " |")
    print("|---|---|" + "---|" * len(args.slack))
    for path in args.results:
        for run in json.loads(path.read_text()):
            choices = [lift_aware(run["checks"], s) for s in args.slack]
            best = choices[0][0]
            cells = ["same" if other is best else describe(other) for _, other in choices]
            print(f"| {run['tag']} | {describe(best)} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
