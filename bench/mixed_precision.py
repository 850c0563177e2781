"""The mixed-precision graph (`sinmdm quantize`) against the float32 one and torch eager:
seconds per motion at the model's default settings and at 50 steps (300 and 742 frames,
interleaved rounds, median), and quality on the clip (the paper's metrics, jitter and
foot skating, no cleanup, the same seeds for both graphs), and a crowd's throughput (16 x 30 s,
`generate` with decoding and cleanup).

    python bench/mixed_precision.py --model runs/X/model_w64.onnx --run runs/X --clip CLIP \
        --results bench/results/mixed_precision_X.json

Writes MODEL_int8.onnx beside the model first when it is not there (the quantize command's
own quality check must pass).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from sampling_speed import TorchDenoiser  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, required=True, help="the float32 .onnx window")
    parser.add_argument("--run", type=Path, help="the training run, for torch eager")
    parser.add_argument("--clip", type=Path, required=True)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeat", type=int, default=7, help="interleaved rounds per timing")
    parser.add_argument("--samples", type=int, default=20, help="motions of twice the clip's length for quality")
    parser.add_argument("--crowd-rounds", type=int, default=2, help="rounds of the 16 x 30 s crowd (generate, decoding included)")
    parser.add_argument("--only-crowd", action="store_true", help="skip the latency and quality rows")
    parser.add_argument("--results", type=Path, required=True)
    args = parser.parse_args()

    from sinmdm.eval.balance import CheckSettings, ClipScorer
    from sinmdm.export.quantize import mixed_name, quantize_model
    from sinmdm.runtime import generate, load_model
    from sinmdm.runtime.bvh import read_bvh
    from sinmdm.runtime.options import SamplingOptions
    from sinmdm.runtime.sampler import sample_features

    mixed_path = args.model.with_name(mixed_name(args.model))
    quantize_check = None
    if not mixed_path.is_file():
        quantize_check = quantize_model([args.model], args.clip, threads=args.threads)
    models = {"float32": load_model(args.model, threads=args.threads), "mixed": load_model(mixed_path, threads=args.threads)}
    base = models["float32"]
    if args.run:
        window = base.trained_window
        models["torch"] = type(base)(**{**base.__dict__, "denoisers": {window: TorchDenoiser(args.run, window, args.threads)}})
    rows = []

    def record(**row):
        rows.append(row)
        print(json.dumps(row), flush=True)

    settings = {"default": SamplingOptions(), "50 steps": SamplingOptions(steps=50, margin=0)}
    for frames in () if args.only_crowd else (300, 742):
        for label, options in settings.items():
            times: dict[str, list[float]] = {name: [] for name in models}
            for name, model in models.items():  # warm-up
                sample_features(model, frames, options)
            for _ in range(args.repeat):
                for name, model in models.items():
                    began = time.perf_counter()
                    sample_features(model, frames, options)
                    times[name].append(time.perf_counter() - began)
            resolved = options.resolve(base, frames)
            medians = {name: round(float(np.median(t)), 3) for name, t in times.items()}
            record(kind="speed", frames=frames, setting=label, steps=resolved.steps, hop=resolved.hop, seconds=medians,
                   spread={name: [round(min(t), 3), round(max(t), 3)] for name, t in times.items()},
                   mixed_speedup=round(medians["float32"] / medians["mixed"], 2),
                   **({"onnxruntime_over_torch": {n: round(medians["torch"] / medians[n], 2) for n in ("float32", "mixed")}}
                      if "torch" in medians else {}))

    crowd_frames = int(round(30 * base.codec.fps))  # 16 motions of 30 s, one call of generate each round
    times = {name: [] for name in ("float32", "mixed")}
    for _ in range(args.crowd_rounds):
        for name in times:
            began = time.perf_counter()
            generate(models[name], crowd_frames, SamplingOptions(count=16))
            times[name].append(time.perf_counter() - began)
    record(kind="crowd", count=16, frames=crowd_frames, rounds=args.crowd_rounds,
           seconds={n: round(float(np.median(t)), 2) for n, t in times.items()},
           frames_per_second={n: round(16 * crowd_frames / float(np.median(t))) for n, t in times.items()})

    reference = read_bvh(args.clip)
    clip_frames = int(round(reference.frames / reference.fps * base.codec.fps))
    scorer = ClipScorer(reference, CheckSettings(samples=args.samples), frames=2 * clip_frames, fps=base.codec.fps,
                        window=base.trained_window)
    for name in () if args.only_crowd else ("float32", "mixed"):
        scores = scorer.check(models[name], steps=base.default_steps, hop=base.default_hop(2 * clip_frames))
        record(kind="quality", graph=name, frames=2 * clip_frames, samples=args.samples, steps=base.default_steps,
               **{k: scores[k] for k in ("coverage", "global_diversity", "local_diversity", "jitter_ratio",
                                         "foot_skating_cm_s", "root_step_max_ratio", "balance", "eval_preset")})
    args.results.parent.mkdir(parents=True, exist_ok=True)
    args.results.write_text(json.dumps({
        "model": str(args.model), "clip": args.clip.name, "threads": args.threads, "repeat": args.repeat,
        "quantize_check": quantize_check, "rows": rows, "date": time.strftime("%Y-%m-%d"), "cpu": os.cpu_count(),
    }, indent=2) + "\n")


if __name__ == "__main__":
    main()
