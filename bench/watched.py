"""The watched training recipe on every trainable clip (issue 14): train with the
`cpu` preset (quality checks every 200 steps, best-balanced checkpoint kept, early
stop), export, sample 20 motions of twice the clip's length with the sampling
defaults the run measured, and score them with the paper's metrics and the
plausibility metrics, for the paper's sampler (`faithful`: no margin, no cleanup)
and the default one.

    python bench/watched.py --work runs/watched --results bench/results/watched.json
    python bench/watched.py --only Crabnew_Crab-dance-long --seeds 0 1000   # run-to-run spread

Per clip it records the wall time of `sinmdm train`, the quality curve (every check
from log.jsonl), the kept step and the sampling defaults. Results are appended per
clip as soon as they are done; finished clips are skipped on a rerun.
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
from bench.quality import SAMPLER_VARIANTS, eval_protocol, export_trained_window, run, sample_and_score  # noqa: E402

# (clip, derived layout): every trainable shared clip (not the keyframe and trajectory
# files) and the project's own derived layout.
CASES = [
    ("Joe_Walk-In-Circle.bvh", None),
    ("Crabnew_Crab-dance-long.bvh", None),
    ("Xia_proud.bvh", None),
    ("Elephant_idle1.bvh", None),
    ("Xia_normal.bvh", None),
    ("Joe_Baseball-Milling-Idle.bvh", None),
    ("Joe_Walk-In-Circle.bvh", "static-root-z-up"),
]


def samples_dir(run_dir: Path, variant: str) -> Path:
    """Where a row's samples are written: "default" -> samples_default, "default hop 32" -> samples_default_hop."""
    return run_dir / ("samples_" + variant.split(" ")[0] + ("_hop" if " hop " in variant else ""))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, default=ROOT / "runs" / "watched")
    parser.add_argument("--results", type=Path, default=ROOT / "bench" / "results" / "watched.json")
    parser.add_argument("--samples", type=int, default=20)
    parser.add_argument("--seeds", nargs="+", type=int, default=[0], help="training seeds (a second: the spread)")
    parser.add_argument("--only", nargs="*", default=None, help="tags to run")
    parser.add_argument("--train-args", nargs=argparse.REMAINDER, default=[])
    args = parser.parse_args()

    from sinmdm.runtime import load_model
    from sinmdm.train.checkpoint import read_log
    from sinmdm.train.trainer import trained_seconds, tried_stages

    results = json.loads(args.results.read_text()) if args.results.exists() else []
    args.results.parent.mkdir(parents=True, exist_ok=True)
    for name, layout in CASES:
        for seed in args.seeds:
            tag = f"{Path(name).stem}{'-' + layout if layout else ''}" + (f"@{seed}" if seed else "")
            if args.only and tag.split("@")[0] not in args.only:
                continue
            if any(r["tag"] == tag for r in results):
                print(f"skip {tag}: already measured", flush=True)
                continue
            clip = derived_clip(name, layout, args.work)
            run_dir = args.work / tag
            config_path = run_dir / "config.json"
            started = config_path.exists()
            finished = started and json.loads(config_path.read_text()).get("finished")
            began = time.perf_counter()
            if not finished:  # a run trained earlier (by this script or by hand) is scored as it is
                run("sinmdm", "train", str(clip), "--out", str(run_dir), "--preset", "cpu", "--seed", str(seed),
                    *(["--resume"] if started else []), *args.train_args)
            config = json.loads(config_path.read_text())
            train_wall = config["elapsed_seconds"] if finished else time.perf_counter() - began
            path = export_trained_window(run_dir, config["window"])
            model = load_model(path)
            steps, protocol = model.default_steps, eval_protocol(clip)
            frames = None
            rows = []
            for variant, options in SAMPLER_VARIANTS.items():
                row = sample_and_score(path, clip, samples_dir(run_dir, variant), steps, args.samples, protocol,
                                       hop=None, **options)
                frames = row["frames"]
                rows.append({"variant": variant, **row})
                print(json.dumps(rows[-1]), flush=True)
            # hop=None above is the hop the run measured (as `sinmdm-run sample` uses it); beside it, half a window
            half = model.denoiser_for(frames).window // 2
            if model.default_hop(frames) not in (None, half):
                for variant, options in SAMPLER_VARIANTS.items():
                    variant = f"{variant} hop {half}"
                    row = sample_and_score(path, clip, samples_dir(run_dir, variant), steps, args.samples,
                                           protocol, hop=half, **options)
                    rows.append({"variant": variant, **row})
            checks = [{"step": r["step"], **r["check"]} for r in read_log(run_dir) if "check" in r]
            stage = config.get("stage")
            stages = tried_stages(config)
            for tried in stages:  # the fallback stages' checks, on the run's step axis
                checks += [{"step": tried["from_step"] + r["step"], "stage": tried["dir"], **r["check"]}
                           for r in read_log(run_dir / tried["dir"]) if "check" in r]
            check_seconds = sum(c["check_seconds"] for c in checks)
            results.append({
                "tag": tag, "clip": name, "layout": layout or "as shared", "seed": seed,
                "train_steps": config["step"] + sum(s["steps"] for s in stages),
                "kept_step": (stage["from_step"] + json.loads((run_dir / stage["dir"] / "config.json").read_text())
                              ["watch"]["best_step"]) if stage and stage["chosen"]
                else (config.get("watch") or {}).get("best_step"),
                "stages": stages,
                "stage": stage, "sampling_chosen": model.metadata.get("sampling_defaults"),
                "stopped": (config.get("watch") or {}).get("stopped"),
                "train_seconds": trained_seconds(run_dir, config),
                "train_wall_seconds": round(train_wall, 1),
                "check_seconds": round(check_seconds, 1), "sampling": config.get("sampling"),
                "checks": checks, "rows": rows, "date": time.strftime("%Y-%m-%d"),
            })
            args.results.write_text(json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    main()
