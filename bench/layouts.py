"""Production layouts benchmark: for each shared clip and derived layout (a static
reference root above the hips, Z-up), train a short model, sample motions of twice
the clip's length and check what an animator sees: per-frame root displacement
against the clip's own, backward walking, feet, floor, jitter (the plausibility
metrics), beside the paper's coverage and diversity.

    python bench/layouts.py --work runs/layouts --results bench/results/layouts.json

Each model is sampled twice, with the same seeds (`--seeds 0 1000` adds a second
set of seeds to every case, without retraining: the run-to-run spread): `faithful` (the paper's sampler:
no edge margin, no foot cleanup) and `default` (what `sinmdm-run sample` does: an
8-frame margin cut off each end, foot-contact cleanup), so every improvement is
measured against the baseline it replaces.

The `as-before` rows force the old assumptions (`--root joint_Root --up y`: the
static root as trajectory joint, the hips as an absolute translation) on the same
clip, so the fix is measured against what it replaced. Results are appended per
case as soon as they are done; finished cases are skipped on a rerun.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.quality import MOTIONS, SAMPLER_VARIANTS, eval_protocol, export_trained_window, run  # noqa: E402
from tests.layouts import LAYOUTS  # noqa: E402

SHARED = ("Joe_Walk-In-Circle.bvh", "Joe_Baseball-Milling-Idle.bvh", "Crabnew_Crab-dance-long.bvh",
          "Elephant_idle1.bvh", "Xia_normal.bvh", "Xia_proud.bvh")
# (clip, layout, extra train options, tag suffix)
CASES = [(name, None, [], "") for name in SHARED] + [
    ("Joe_Walk-In-Circle.bvh", "static-root-z-up", [], ""),
    ("Joe_Walk-In-Circle.bvh", "static-root-z-up", ["--root", "joint_Root", "--up", "y"], "-as-before"),
    ("Xia_normal.bvh", "static-root", [], ""),
] + [  # the root velocity in metres per second (runtime.features.model_scale) against the paper's per frame
    (name, layout, ["--velocity-unit", "second"], "-per-second")
    for name, layout in (("Joe_Walk-In-Circle.bvh", None), ("Crabnew_Crab-dance-long.bvh", None),
                         ("Joe_Baseball-Milling-Idle.bvh", None), ("Xia_proud.bvh", None),
                         ("Joe_Walk-In-Circle.bvh", "static-root-z-up"))
]


def derived_clip(name: str, layout: str | None, work: Path) -> Path:
    from sinmdm.runtime.bvh import read_bvh, write_bvh

    if layout is None:
        return MOTIONS / name
    path = work / f"{Path(name).stem}-{layout}.bvh"
    if not path.exists():
        work.mkdir(parents=True, exist_ok=True)
        write_bvh(path, LAYOUTS[layout](read_bvh(MOTIONS / name)))
    return path


KEYS = ("coverage", "global_diversity", "local_diversity")


def score(clip: Path, paths: list[Path], preset: str) -> dict:
    from sinmdm.eval.motion_features import evaluate_files

    scores = evaluate_files(clip, paths, preset=preset)
    return {**{k: scores[k] for k in KEYS}, "plausibility": scores.get("plausibility")}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, default=ROOT / "runs" / "layouts")
    parser.add_argument("--results", type=Path, default=ROOT / "bench" / "results" / "layouts.json")
    parser.add_argument("--train-steps", type=int, default=400)
    parser.add_argument("--width", type=int, default=128)
    parser.add_argument("--samples", type=int, default=8)
    parser.add_argument("--only", nargs="*", default=None, help="tags to run")
    parser.add_argument("--rescore", action="store_true", help="score the samples already written again")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0],
                        help="first seed of each set of samples; a second set gives the run-to-run spread")
    args = parser.parse_args()

    from sinmdm.runtime import load_model, read_bvh

    results = json.loads(args.results.read_text()) if args.results.exists() else []
    args.results.parent.mkdir(parents=True, exist_ok=True)
    for name, layout, extra, suffix in CASES:
        tag = f"{Path(name).stem}-{layout or 'as-shared'}{suffix}"
        if args.only and tag not in args.only:
            continue
        clip = derived_clip(name, layout, args.work)
        run_dir = args.work / tag
        row = next((r for r in results if r["tag"] == tag), None)
        if row is None:
            began = time.perf_counter()
            done = run_dir / "config.json"
            finished = done.exists() and json.loads(done.read_text()).get("finished")
            if not finished:  # a finished run (the same command, run before) is scored as it is
                run("sinmdm", "train", str(clip), "--out", str(run_dir), "--preset", "cpu", "--steps", str(args.train_steps),
                    "--width", str(args.width), "--checkpoint-every", str(args.train_steps), *extra,
                    *(["--resume"] if done.exists() else []))
            config = json.loads(done.read_text())
            train_wall = time.perf_counter() - began if not finished else config["elapsed_seconds"]
            reference = read_bvh(clip)
            fps = load_model(export_trained_window(run_dir, config["window"])).codec.fps
            row = {"tag": tag, "clip": name, "layout": layout or "as shared", "train_options": extra,
                   "train_steps": config["step"], "width": args.width, "train_wall_seconds": round(train_wall, 1),
                   "samples": args.samples, "frames": 2 * round(reference.frames / reference.fps * fps),
                   "eval_preset": eval_protocol(clip), "variants": {}, "date": time.strftime("%Y-%m-%d")}
            results.append(row)
        config = json.loads((run_dir / "config.json").read_text())
        model = load_model(run_dir / f"model_w{config['window']}.onnx")
        for seed in args.seeds:
            for variant, options in SAMPLER_VARIANTS.items():
                key = variant if seed == 0 else f"{variant}@{seed}"
                if key in row["variants"] and not args.rescore:
                    continue
                folder = run_dir / f"samples-{key}"
                if not args.rescore:
                    sample(model, row["frames"], row["samples"], seed, options, folder)
                paths = sorted(folder.glob("*.bvh"))
                row["variants"][key] = {"options": options, "seed": seed, **score(clip, paths, row["eval_preset"])}
                args.results.write_text(json.dumps(results, indent=2) + "\n")
        print(json.dumps({k: v for k, v in row.items() if k != "variants"}), flush=True)


def sample(model, frames: int, count: int, seed: int, options: dict, folder: Path) -> None:
    from sinmdm.runtime import SamplingOptions, generate, write_outputs

    result = generate(model, frames, SamplingOptions(count=count, seed=seed, **options))
    write_outputs(model, result, folder, force=True)


if __name__ == "__main__":
    main()
