"""Production layouts benchmark: for each shared clip and derived layout (a static
reference root above the hips, Z-up), train a short model, sample motions of twice
the clip's length and check what an animator sees: per-frame root displacement
against the clip's own, backward walking, feet, floor, jitter (the plausibility
metrics), beside the paper's coverage and diversity.

    python bench/layouts.py --work runs/layouts --results bench/results/layouts.json

Each model is sampled twice, with the same seeds: `faithful` (the paper's sampler:
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

from bench.quality import MOTIONS, eval_protocol, export_trained_window, run  # noqa: E402
from tests.layouts import LAYOUTS  # noqa: E402

SHARED = ("Joe_Walk-In-Circle.bvh", "Joe_Baseball-Milling-Idle.bvh", "Crabnew_Crab-dance-long.bvh",
          "Elephant_idle1.bvh", "Xia_normal.bvh", "Xia_proud.bvh")
# (clip, layout, extra train options, tag suffix)
CASES = [(name, None, [], "") for name in SHARED] + [
    ("Joe_Walk-In-Circle.bvh", "static-root-z-up", [], ""),
    ("Joe_Walk-In-Circle.bvh", "static-root-z-up", ["--root", "joint_Root", "--up", "y"], "-as-before"),
    ("Xia_normal.bvh", "static-root", [], ""),
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


VARIANTS = {"faithful": {"margin": 0, "cleanup": False}, "default": {}}
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
    args = parser.parse_args()

    from sinmdm.runtime import GenerationRequest, generate, load_model, read_bvh, write_outputs

    results = json.loads(args.results.read_text()) if args.results.exists() else []
    args.results.parent.mkdir(parents=True, exist_ok=True)
    if args.rescore:
        for row in results:
            clip = derived_clip(row["clip"], None if row["layout"] == "as shared" else row["layout"], args.work)
            for variant, scores in row["variants"].items():
                paths = sorted((args.work / row["tag"] / f"samples-{variant}").glob("*.bvh"))
                scores.update(score(clip, paths, row["eval_preset"]))
        args.results.write_text(json.dumps(results, indent=2) + "\n")
        return
    for name, layout, extra, suffix in CASES:
        tag = f"{Path(name).stem}-{layout or 'as-shared'}{suffix}"
        if any(r["tag"] == tag for r in results) or (args.only and tag not in args.only):
            continue
        clip = derived_clip(name, layout, args.work)
        run_dir = args.work / tag
        began = time.perf_counter()
        run("sinmdm", "train", str(clip), "--out", str(run_dir), "--preset", "cpu", "--steps", str(args.train_steps),
            "--width", str(args.width), "--checkpoint-every", str(args.train_steps), *extra,
            *(["--resume"] if (run_dir / "config.json").exists() else []))
        train_wall = time.perf_counter() - began
        config = json.loads((run_dir / "config.json").read_text())
        model = load_model(export_trained_window(run_dir, config["window"]))
        reference = read_bvh(clip)
        frames = 2 * round(reference.frames / reference.fps * model.codec.fps)
        variants = {}
        for variant, options in VARIANTS.items():
            result = generate(model, GenerationRequest(frames=frames, count=args.samples, seed=0, **options))
            paths = write_outputs(model, result, run_dir / f"samples-{variant}", force=True)
            variants[variant] = {"options": options, **score(clip, paths, eval_protocol(name))}
        results.append({
            "tag": tag, "clip": name, "layout": layout or "as shared", "train_options": extra,
            "train_steps": config["step"], "width": args.width, "train_wall_seconds": round(train_wall, 1),
            "samples": args.samples, "frames": frames, "eval_preset": eval_protocol(name),
            "variants": variants, "date": time.strftime("%Y-%m-%d"),
        })
        print(json.dumps({k: v for k, v in results[-1].items() if k != "variants"}), flush=True)
        args.results.write_text(json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    main()
