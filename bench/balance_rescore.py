"""Which check each watched run would keep under the balance with and without its jitter
term, replayed on the checks those runs logged (bench/results/watched.json), with the
keep rule of sinmdm.train.watch. No training: it reads the logged scores.

    python bench/balance_rescore.py
"""

from __future__ import annotations

import json
from pathlib import Path

from sinmdm.eval.balance import balance, keepable

RESULTS = Path(__file__).resolve().parent / "results" / "watched.json"


def kept(checks: list[dict], with_jitter: bool) -> dict:
    def score(check: dict) -> float:
        return balance(check["coverage"], check["global_diversity"], check["jitter_ratio"] if with_jitter else None)

    return max((c for c in checks if keepable(c)), key=score)


def main() -> None:
    print("| clip | balance | kept step | coverage % | global div | jitter (x clip) | skating cm/s |")
    print("|---|---|---|---|---|---|---|")
    for run in json.loads(RESULTS.read_text()):
        for label, with_jitter in (("coverage, diversity", False), ("with jitter", True)):
            c = kept(run["checks"], with_jitter)
            print(f"| {run['tag']} | {label} | {c['step']} | {c['coverage']:.1f} | {c['global_diversity']:.2f} | "
                  f"{c['jitter_ratio']:.2f} | {c['foot_skating_cm_s']:.1f} |")


if __name__ == "__main__":
    main()
