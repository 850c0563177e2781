"""CPU-recipe ablations: train one clip with the `cpu` preset plus overrides, export,
sample 20 motions of twice the clip's length and score them, like bench/quality.py.

    python bench/recipe_ablation.py --clip Joe_Walk-In-Circle.bvh --tag rescale \
        --set rescale=0.75,1.25 --work runs/recipe --results bench/results/recipe.json

`--layout static-root-z-up` trains a layout derived from the clip (bench/layouts.py).
`--set KEY=VALUE` overrides any TrainConfig field (steps, crop, rescale, lr, lr_schedule,
ema, norm, dropout, width, batch, ...). Finished tags are skipped; an interrupted
training resumes. `--run DIR` scores a finished run (the baseline) the same way, without
training.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import fields
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from layouts import derived_clip  # noqa: E402
from quality import ROOT, eval_protocol, export_trained_window, sample_and_score  # noqa: E402


def parse_override(config_type, text: str) -> tuple[str, object]:
    key, _, raw = text.partition("=")
    kinds = {f.name: f.type for f in fields(config_type)}
    if key not in kinds:
        raise SystemExit(f"unknown TrainConfig field {key!r}")
    kind = str(kinds[key])
    if raw.lower() == "none":
        return key, None
    if "tuple" in kind:
        return key, tuple(float(v) for v in raw.split(","))
    if "bool" in kind:
        return key, raw.lower() in ("1", "true", "yes")
    if "int" in kind and "." not in raw:
        return key, int(raw)
    if "float" in kind:
        return key, float(raw)
    return key, raw


def main() -> None:
    from sinmdm.runtime import load_model
    from sinmdm.train.presets import TrainConfig, preset
    from sinmdm.train.trainer import load_config, train

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clip", required=True)
    parser.add_argument("--tag", required=True)
    parser.add_argument("--layout", default=None, help="a derived layout of the clip (bench/layouts.py)")
    parser.add_argument("--set", dest="overrides", action="append", default=[])
    parser.add_argument("--seed", type=int, default=0, help="training seed")
    parser.add_argument("--samples", type=int, default=20)
    parser.add_argument("--steps", type=int, default=50, help="sampling steps (0: the steps the run calibrated)")
    parser.add_argument("--faithful", action="store_true",
                        help="also score the paper's sampler (no margin, no cleanup): foot skating before cleanup")
    parser.add_argument("--run", type=Path, default=None,
                        help="score this finished run (the baseline) instead of training one")
    parser.add_argument("--work", type=Path, default=ROOT / "runs" / "recipe")
    parser.add_argument("--results", type=Path, default=ROOT / "bench" / "results" / "recipe.json")
    args = parser.parse_args()

    overrides = dict(parse_override(TrainConfig, text) for text in args.overrides)
    config = TrainConfig.from_dict({**preset("cpu").to_dict(), **overrides})  # keeps explicit Nones
    results = json.loads(args.results.read_text()) if args.results.exists() else []
    tag = f"{Path(args.clip).stem}{'-' + args.layout if args.layout else ''}-{args.tag}" + (f"@{args.seed}" if args.seed else "")
    if any(r["tag"] == tag for r in results):
        print(f"skip {tag}: already measured")
        return
    run_dir = args.run or args.work / tag
    clip = derived_clip(args.clip, args.layout, args.work)
    began = time.perf_counter()
    if args.run is None:
        train(clip, run_dir, config, seed=args.seed, device="cpu", resume=(run_dir / "config.json").exists())
    train_wall = time.perf_counter() - began
    run_config = load_config(run_dir)
    model = export_trained_window(run_dir, run_config["window"])
    steps = args.steps or load_model(model).default_steps
    row = sample_and_score(model, clip, run_dir / f"samples_{steps}", steps, args.samples, eval_protocol(clip))
    rows = [row]
    if args.faithful:
        rows.append(sample_and_score(model, clip, run_dir / f"samples_{steps}_faithful", steps,
                                     args.samples, eval_protocol(clip), margin=0, cleanup=False, smooth=0.0))
    print(json.dumps(rows))
    # read again: other ablations may have finished (and appended) while this one trained
    results = json.loads(args.results.read_text()) if args.results.exists() else []
    results.append({
        "tag": tag, "clip": args.clip, "layout": args.layout or "as shared", "variant": args.tag, "overrides": args.overrides, "seed": args.seed,
        "train_steps": run_config["step"], "train_seconds": run_config["elapsed_seconds"],
        "train_wall_seconds": round(train_wall, 1) if args.run is None else None, "window": run_config["window"],
        "threads": int(os.environ.get("OMP_NUM_THREADS", "0")),
        "rows": rows, "date": time.strftime("%Y-%m-%d"),
    })
    args.results.parent.mkdir(parents=True, exist_ok=True)
    args.results.write_text(json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    main()
