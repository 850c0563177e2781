"""Sampling speed: seconds per sample against steps and length, onnxruntime against
torch eager running the same sampler, and peak memory of a 10-minute motion.

    python bench/sampling_speed.py --model runs/quality/X/model_w64.onnx --run runs/quality/X \
        --results bench/results/sampling_speed.json

Times are medians of --repeat in-process runs after one warm-up; peak memory is
the maximum resident set size of a separate `sinmdm-run sample` process,
measured with /usr/bin/time -v.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def median_seconds(fn, repeat: int) -> float:
    fn()  # warm-up
    times = []
    for _ in range(repeat):
        began = time.perf_counter()
        fn()
        times.append(time.perf_counter() - began)
    return float(np.median(times))


class TorchDenoiser:
    """The run's torch model behind the runtime's denoiser interface (eager, fp32)."""

    def __init__(self, run_dir: Path, window: int, threads: int):
        import torch

        from sinmdm.train.trainer import load_trained_model

        torch.set_num_threads(threads)
        self.torch = torch
        self.model, _ = load_trained_model(run_dir)
        self.window = window
        self.path = run_dir

    def __call__(self, x_t: np.ndarray, t: np.ndarray) -> np.ndarray:
        with self.torch.inference_mode():
            return self.model(self.torch.from_numpy(x_t), self.torch.from_numpy(t)).numpy()


def peak_memory_mb(model: Path, frames: int, steps: int) -> tuple[float, float]:
    exe = Path(sys.executable).parent / "sinmdm-run"
    with tempfile.TemporaryDirectory() as out:
        began = time.perf_counter()
        result = subprocess.run(
            ["/usr/bin/time", "-v", str(exe), "sample", str(model), "--frames", str(frames), "--steps", str(steps),
             "--out", out], capture_output=True, text=True, check=True)
        wall = time.perf_counter() - began
    rss_kb = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", result.stderr).group(1))
    return rss_kb / 1024, wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, required=True)
    parser.add_argument("--run", type=Path, help="the training run, for the torch eager comparison")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--results", type=Path, default=Path("bench/results/sampling_speed.json"))
    parser.add_argument("--skip-1000", action="store_true")
    args = parser.parse_args()

    from sinmdm.runtime import load_model
    from sinmdm.runtime.options import SamplingOptions
    from sinmdm.runtime.sampler import sample_features

    model = load_model(args.model, threads=args.threads)
    rows = []

    def record(**row):
        rows.append(row)
        print(json.dumps(row), flush=True)

    for steps in ([20, 50, 100] if args.skip_1000 else [20, 50, 100, 1000]):
        repeat = 1 if steps == 1000 else args.repeat
        seconds = median_seconds(lambda: sample_features(model, 300, SamplingOptions(steps=steps, margin=0)), repeat)
        record(kind="steps", frames=300, steps=steps, backend="onnxruntime", seconds_per_sample=round(seconds, 3))
    for frames in (300, 742):
        seconds = median_seconds(lambda: sample_features(model, frames, SamplingOptions(steps=50, margin=0)), args.repeat)
        record(kind="length", frames=frames, steps=50, backend="onnxruntime", seconds_per_sample=round(seconds, 3))
    crowd = median_seconds(lambda: sample_features(model, 300, SamplingOptions(count=16, steps=50, margin=0)), 1)
    record(kind="crowd", frames=300, steps=50, count=16, backend="onnxruntime", seconds_per_sample=round(crowd / 16, 3))
    if args.run:
        window = model.trained_window
        torch_model = type(model)(**{**model.__dict__, "denoisers": {window: TorchDenoiser(args.run, window, args.threads)}})
        for frames in (300, 742):
            ort_s = median_seconds(lambda: sample_features(model, frames, SamplingOptions(steps=50, margin=0)), args.repeat)
            torch_s = median_seconds(lambda: sample_features(torch_model, frames, SamplingOptions(steps=50, margin=0)), args.repeat)
            record(kind="backend", frames=frames, steps=50, onnxruntime=round(ort_s, 3), torch_eager=round(torch_s, 3),
                   speedup=round(torch_s / ort_s, 2))
    ten_minutes = int(600 * model.codec.fps)
    rss, wall = peak_memory_mb(args.model, ten_minutes, 50)
    record(kind="ten_minutes", frames=ten_minutes, steps=50, peak_rss_mb=round(rss, 1), wall_seconds=round(wall, 1))
    args.results.parent.mkdir(parents=True, exist_ok=True)
    args.results.write_text(json.dumps({"model": str(args.model), "threads": args.threads, "rows": rows,
                                        "date": time.strftime("%Y-%m-%d"), "cpu": os.cpu_count()}, indent=2) + "\n")


if __name__ == "__main__":
    main()
