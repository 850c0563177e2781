"""One picture of shaking: a joint's speed over the first seconds of one sample from each model,
sampled as `sinmdm-run sample` does (each model's own steps, hop, smoothing; cleanup on), beside
the clip's own. The joint is the one whose jerk the first model's samples most exceed the clip's.

    python bench/jitter_plot.py --clip ../shared/motions/Xia_normal.bvh \
        --model crops=runs/default_1207/Xia_normal/model_w64.onnx \
        --model whole=runs/crop96_1207/Xia_normal/model_w90.onnx --out docs/whole_clip_xia.png
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from bench.jitter_sources import joint_jerk
from sinmdm.runtime import SamplingOptions, generate, load_model, read_bvh
from sinmdm.runtime.animation import animation_from_bvh, global_positions
from sinmdm.runtime.features import resample_animation


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clip", type=Path, required=True)
    parser.add_argument("--model", action="append", required=True, help="LABEL=PATH (repeat)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    clip = animation_from_bvh(read_bvh(args.clip))
    models = [(label, load_model(Path(path))) for label, path in (m.split("=", 1) for m in args.model)]
    fps = models[0][1].codec.fps
    frames = 2 * round(clip.frames / clip.fps * fps)
    samples = [(label, animation_from_bvh(generate(model, frames, SamplingOptions(seed=args.seed)).clips[0]))
               for label, model in models]
    clip_jerk = joint_jerk(clip, fps)
    joint = int(np.argmax(joint_jerk(samples[0][1], fps) / np.maximum(clip_jerk, 1e-9)))
    span = slice(0, min(frames, int(args.seconds * fps)))
    fig, axis = plt.subplots(figsize=(8, 3.4))
    for label, sample in samples:
        p = global_positions(resample_animation(sample, fps))[span, joint]
        ratio = joint_jerk(sample, fps)[joint] / max(clip_jerk[joint], 1e-9)
        axis.plot(np.linalg.norm(np.diff(p, axis=0), axis=-1) * fps, label=f"{label} (this joint's jerk {ratio:.1f}x the clip's)")
    own = global_positions(resample_animation(clip, fps))[span, joint]
    axis.plot(np.linalg.norm(np.diff(own, axis=0), axis=-1) * fps, color="0.6", lw=1, label="the clip (its first seconds)")
    axis.set_ylabel(f"{clip.skeleton.names[joint].split(':')[-1]} speed (units/s)")
    axis.set_xlabel(f"frame at {fps:g} fps")
    axis.legend(fontsize=8)
    axis.set_title(f"{args.clip.stem}: one sample each (seed {args.seed}, as `sample` runs)", fontsize=10)
    fig.tight_layout()
    fig.savefig(args.out, dpi=90)
    print(f"wrote {args.out}: joint {clip.skeleton.names[joint]}")


if __name__ == "__main__":
    main()
