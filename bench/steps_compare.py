"""Fast default against the faithful 1000-step chain, same model, same seeds.

    python bench/steps_compare.py --run runs/quality/Joe_Walk-In-Circle-cpu \
        --clip Joe_Walk-In-Circle.bvh --steps 1000 50 20 --samples 3
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from quality import MOTIONS, eval_protocol, sample_and_score


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", type=Path, required=True)
    parser.add_argument("--clip", required=True)
    parser.add_argument("--steps", nargs="+", type=int, default=[1000, 50, 20])
    parser.add_argument("--samples", type=int, default=3)
    parser.add_argument("--hop", type=int, default=None,
                        help="window hop (default: the one the model measured, else half a window)")
    parser.add_argument("--sampler", default="ddpm", choices=["ddpm", "ddim"])
    parser.add_argument("--no-cleanup", action="store_true", help="sample without the foot cleanup")
    parser.add_argument("--results", type=Path, default=Path(__file__).resolve().parent / "results" / "steps_compare.json")
    args = parser.parse_args()
    config = json.loads((args.run / "config.json").read_text())
    model = args.run / f"model_w{config['window']}.onnx"
    preset = eval_protocol(args.clip)
    rows = []
    for steps in args.steps:
        out = args.run / (f"compare_{args.sampler}_{steps}_hop{args.hop or 'model'}"
                          + ("_nocleanup" if args.no_cleanup else ""))
        options = {"cleanup": False} if args.no_cleanup else {}
        rows.append(sample_and_score(model, MOTIONS / args.clip, out, steps, args.samples, preset,
                                     hop=args.hop, sampler=args.sampler, **options))
        print(json.dumps(rows[-1]), flush=True)
    previous = json.loads(args.results.read_text()) if args.results.exists() else []
    previous.append({"clip": args.clip, "run": args.run.name, "rows": rows, "date": time.strftime("%Y-%m-%d")})
    args.results.parent.mkdir(parents=True, exist_ok=True)
    args.results.write_text(json.dumps(previous, indent=2) + "\n")


if __name__ == "__main__":
    main()
