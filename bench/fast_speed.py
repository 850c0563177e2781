"""A/B wall time of the default sampling options against the fast ones, same model,
same process, interleaved repetitions (robust to a busy machine: read the ratio).

    python bench/fast_speed.py --model runs/quality/Joe_Walk-In-Circle-cpu/model_w64.onnx --frames 742
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

from sinmdm.runtime import SamplingOptions, generate, load_model

VARIANTS = {"default (50 steps, hop 32)": dict(steps=50), "fast (20 steps, hop 48)": dict(steps=20, hop=48)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, required=True)
    parser.add_argument("--frames", type=int, default=742)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--results", type=Path, default=Path(__file__).resolve().parent / "results" / "fast_speed.json")
    args = parser.parse_args()
    model = load_model(args.model)
    generate(model, args.frames, SamplingOptions(steps=2))  # warm-up
    times: dict[str, list[float]] = {name: [] for name in VARIANTS}
    for seed in range(args.repeats):
        for name, options in VARIANTS.items():
            began = time.perf_counter()
            generate(model, args.frames, SamplingOptions(seed=seed, **options))
            times[name].append(time.perf_counter() - began)
    medians = {name: statistics.median(values) for name, values in times.items()}
    first, second = medians.values()
    result = {"model": args.model.name, "frames": args.frames, "seconds": times, "medians": medians,
              "ratio": first / second, "date": time.strftime("%Y-%m-%d")}
    print(json.dumps(result, indent=2))
    args.results.write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
