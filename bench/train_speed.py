"""Seconds per training iteration of each preset on real clips (this machine), eager and
through torch.compile (the `cpu` preset; the first compiled step, which builds the graph, is
reported on its own).

    python bench/train_speed.py --clips Joe_Walk-In-Circle.bvh Crabnew_Crab-dance-long.bvh \
        --results bench/results/train_speed.json
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np
import torch

from sinmdm.train.presets import preset
from sinmdm.train.trainer import Run, load_clip, resolve_device

MOTIONS = Path(__file__).resolve().parents[2] / "shared" / "motions"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clips", nargs="+", required=True)
    parser.add_argument("--presets", nargs="+", default=["cpu", "paper"])
    parser.add_argument("--iterations", type=int, default=5)
    parser.add_argument("--compile-modes", nargs="+", default=["off", "on"], help="off = eager, on = torch.compile")
    parser.add_argument("--results", type=Path, default=Path("bench/results/train_speed.json"))
    args = parser.parse_args()
    torch.set_num_threads(int(os.environ.get("OMP_NUM_THREADS", os.cpu_count())))
    rows = []
    for name in args.clips:
        for preset_name in args.presets:
            for mode in args.compile_modes if preset_name == "cpu" else ["off"]:
                config = preset(preset_name)
                clip = load_clip(MOTIONS / name, config.fps, {})
                run = Run(clip, config, seed=0, device=resolve_device("auto"), compile_mode=mode)
                iterations = args.iterations if preset_name == "cpu" else max(2, args.iterations // 2)
                began = time.perf_counter()
                run.train_step()  # warm-up (and, compiled, the graph's construction)
                first = time.perf_counter() - began
                times = []
                for _ in range(iterations):
                    began = time.perf_counter()
                    run.train_step()
                    times.append(time.perf_counter() - began)
                median = float(np.median(times))
                row = {"clip": name, "preset": preset_name, "features": clip.codec.width, "frames": clip.features.shape[0],
                       "window": run.sampler.window, "bf16": run.autocast, "compiled": run.forward.compiled,
                       "first_step_seconds": round(first, 1), "seconds_per_iteration": round(median, 3),
                       "iterations_timed": iterations, "steps": config.steps,
                       "full_run_hours": round((first + median * (config.steps - 1)) / 3600, 2)}
                rows.append(row)
                print(json.dumps(row), flush=True)
    args.results.parent.mkdir(parents=True, exist_ok=True)
    args.results.write_text(json.dumps({"rows": rows, "date": time.strftime("%Y-%m-%d"), "threads": torch.get_num_threads()}, indent=2) + "\n")


if __name__ == "__main__":
    main()
