"""Recompute the plausibility figures and verdicts of a watched benchmark's saved samples with
today's metrics (a metric added after the samples were scored, e.g. pace), in place. The paper's
metrics are not touched: the samples are the same files.

    python bench/rescore_plausibility.py --results bench/results/watched_as_sampled_2026-12-07.json \
        --work runs/as_sampled
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.layouts import derived_clip  # noqa: E402
from bench.watched import samples_dir  # noqa: E402


def main() -> None:
    from sinmdm.eval.plausibility import plausibility
    from sinmdm.runtime import read_bvh

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=Path, required=True)
    parser.add_argument("--work", type=Path, required=True)
    args = parser.parse_args()
    entries = json.loads(args.results.read_text())
    for entry in entries:
        clip = read_bvh(derived_clip(entry["clip"], None if entry["layout"] == "as shared" else entry["layout"], args.work))
        for row in entry["rows"]:
            folder = samples_dir(args.work / entry["tag"], row["variant"])
            files = sorted(folder.glob("*.bvh"))
            if len(files) != row["samples"]:
                print(f"skip {entry['tag']} {row['variant']}: {len(files)} files in {folder}", flush=True)
                continue
            scored = plausibility(clip, [read_bvh(f) for f in files])
            row["plausibility"] = scored["aggregate"]
            row["verdicts"] = [r["verdict"] for r in scored["samples"]]
            row["plausibility_rescored"] = time.strftime("%Y-%m-%d")
            print(entry["tag"], row["variant"], "rescored", flush=True)
    args.results.write_text(json.dumps(entries, indent=2) + "\n")


if __name__ == "__main__":
    main()
