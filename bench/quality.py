"""Quality benchmark: for each clip, train (a preset), export, sample 20 motions of
twice the clip's length, and score them with the paper's metrics.

    python bench/quality.py --clips Joe_Walk-In-Circle.bvh Crabnew_Crab-dance-long.bvh \
        --preset cpu --steps-list 50 1000 --work runs/quality --results bench/results/quality.json

Each clip's result is appended to the JSON results file as soon as it is done, so a
long benchmark can be stopped and resumed (finished clips are skipped).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MOTIONS = ROOT.parent / "shared" / "motions"
# The paper's sampler (no edge margin, no foot cleanup) and what `sinmdm-run sample` does.
SAMPLER_VARIANTS = {"faithful": {"margin": 0, "cleanup": False, "smooth": 0.0}, "default": {}}


def run(*args: str) -> None:
    bin_dir = Path(sys.executable).parent
    subprocess.run([str(bin_dir / args[0]), *args[1:]], check=True)


def eval_protocol(clip: str | Path) -> str:
    """The protocol a clip is scored with, as sinmdm chooses it (`eval.balance.eval_preset`: the
    paper's mixamo24 for a Mixamo skeleton whose units its rule reads right). A bare file name is
    a shared clip; a derived layout is passed as its path."""
    from sinmdm.eval.balance import eval_preset
    from sinmdm.runtime import read_bvh

    path = Path(clip)
    return eval_preset(read_bvh(MOTIONS / path if path.parent == Path(".") else path))


def export_trained_window(run_dir: Path, window: int) -> Path:
    """Export a run at its training window (the export default); the written graph's path."""
    run("sinmdm", "export", str(run_dir), "--out", str(run_dir / "model.onnx"), "--force")
    return run_dir / f"model_w{window}.onnx"


def sample_and_score(model: Path, clip: Path, out: Path, steps: int, count: int, preset: str,
                     hop: int | None = None, sampler: str = "ddpm", **options) -> dict:
    """Sample `count` motions (seeds 0..count-1; `options`: more SamplingOptions fields,
    e.g. margin=0, cleanup=False for the paper's sampler) and score them: the paper's
    metrics and the plausibility aggregate."""
    from sinmdm.eval.motion_features import evaluate_files
    from sinmdm.runtime import SamplingOptions, generate, load_model, read_bvh, write_outputs

    loaded = load_model(model)
    reference = read_bvh(clip)
    frames = 2 * round(reference.frames / reference.fps * loaded.codec.fps)
    began = time.perf_counter()
    chosen = SamplingOptions(count=count, seed=0, steps=steps, hop=hop, sampler=sampler, **options)
    result = generate(loaded, frames, chosen)
    seconds = time.perf_counter() - began
    paths = write_outputs(loaded, result, out, force=True)
    scores = evaluate_files(clip, paths, preset=preset)
    keys = ("coverage", "global_diversity", "local_diversity", "inter_diversity", "intra_diversity_diff")
    return {**{k: scores[k] for k in keys}, "steps": steps, "samples": count, "frames": frames,
            "sampling_seconds": round(seconds, 2), "eval_preset": preset,
            # the hop actually used: hop=None takes the model's measured hop, else half a window
            "hop": chosen.resolve(loaded, frames).hop or loaded.denoiser_for(frames).window // 2, "sampler": sampler, "options": options,
            "plausibility": (scores.get("plausibility") or {}).get("aggregate"),
            "verdicts": [r["verdict"] for r in (scores.get("plausibility") or {}).get("samples", [])]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clips", nargs="+", required=True)
    parser.add_argument("--preset", default="cpu")
    parser.add_argument("--train-steps", type=int, default=None)
    parser.add_argument("--steps-list", nargs="+", type=int, default=[50])
    parser.add_argument("--samples", type=int, default=20)
    parser.add_argument("--samples-1000", type=int, default=5, help="samples for the 1000-step rows (slow)")
    parser.add_argument("--work", type=Path, default=ROOT / "runs" / "quality")
    parser.add_argument("--results", type=Path, default=ROOT / "bench" / "results" / "quality.json")
    parser.add_argument("--train-args", nargs=argparse.REMAINDER, default=[])
    args = parser.parse_args()

    results = json.loads(args.results.read_text()) if args.results.exists() else []
    args.results.parent.mkdir(parents=True, exist_ok=True)
    for name in args.clips:
        clip = MOTIONS / name
        tag = f"{Path(name).stem}-{args.preset}"
        if any(r["tag"] == tag for r in results):
            print(f"skip {tag}: already measured")
            continue
        run_dir = args.work / tag
        extra = ["--steps", str(args.train_steps)] if args.train_steps else []
        began = time.perf_counter()
        if not (run_dir / "config.json").exists():
            run("sinmdm", "train", str(clip), "--out", str(run_dir), "--preset", args.preset, *extra, *args.train_args)
        else:
            run("sinmdm", "train", str(clip), "--out", str(run_dir), "--preset", args.preset, "--resume", *extra, *args.train_args)
        train_wall = time.perf_counter() - began
        config = json.loads((run_dir / "config.json").read_text())
        model = export_trained_window(run_dir, config["window"])
        preset = eval_protocol(name)
        rows = []
        for steps in args.steps_list:
            count = args.samples if steps < 1000 else args.samples_1000
            for variant, options in SAMPLER_VARIANTS.items():
                rows.append({"variant": variant, **sample_and_score(
                    model, clip, run_dir / f"samples_{steps}_{variant}", steps, count, preset, **options)})
                print(json.dumps(rows[-1]))
        results.append({
            "tag": tag, "clip": name, "preset": args.preset, "train_steps": config["step"],
            "train_seconds": config["elapsed_seconds"], "train_wall_seconds": round(train_wall, 1),
            "window": config["window"], "features": config["model"]["features"],
            "parameters": config["parameters"], "rows": rows,
            "date": time.strftime("%Y-%m-%d"),
        })
        args.results.write_text(json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    main()
