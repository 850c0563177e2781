"""Toe bend against the clip's range: the angle between each foot bone (Foot -> ToeBase) and
toe bone (ToeBase -> Toe_End) of sampled motions, with the cleanup's toe aim capped at
several `PIVOT_TURN`s (and the cleanup off), against the range the training clip bends through,
with the foot skating each cap leaves.

    python bench/toe_bend.py --model runs/layouts_1205/Joe_Walk-In-Circle-as-shared/model_w64.onnx \
        --clip ../shared/motions/Joe_Walk-In-Circle.bvh --caps inf 0.5 0.25 --figure docs/toe_bend.png
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

SIDES = ("Left", "Right")
MARGIN = 5.0  # degrees outside the clip's range before a frame counts


def toe_bends(animation) -> np.ndarray:
    """(T, 2) degrees: left and right angle between the foot bone and the toe bone."""
    from sinmdm.runtime.animation import global_positions

    names, positions, out = animation.skeleton.names, global_positions(animation), []
    for side in SIDES:
        joints = [next(i for i, n in enumerate(names) if n.endswith(side + part)) for part in ("Foot", "ToeBase", "Toe_End")]
        p = positions[:, joints]
        foot, toe = p[:, 1] - p[:, 0], p[:, 2] - p[:, 1]
        out.append(np.degrees(np.arctan2(np.linalg.norm(np.cross(foot, toe), axis=-1), (foot * toe).sum(-1))))
    return np.stack(out, axis=1)


def main() -> None:
    import sinmdm.runtime.cleanup as cleanup
    from sinmdm.eval.plausibility import plausibility
    from sinmdm.runtime import SamplingOptions, generate, load_model, read_bvh
    from sinmdm.runtime.animation import animation_from_bvh

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, required=True)
    parser.add_argument("--clip", type=Path, required=True)
    parser.add_argument("--caps", nargs="+", type=float, default=[float("inf"), cleanup.PIVOT_TURN])
    parser.add_argument("--samples", type=int, default=4)
    parser.add_argument("--figure", type=Path, default=None)
    parser.add_argument("--results", type=Path, default=None)
    args = parser.parse_args()

    model = load_model(args.model)
    reference_bvh = read_bvh(args.clip)
    reference = animation_from_bvh(reference_bvh)
    frames = 2 * round(reference.frames / reference.fps * model.codec.fps)  # twice the clip, at the model's rate
    clip = toe_bends(reference)
    low, high = clip.min(axis=0), clip.max(axis=0)
    print(f"clip range: left {low[0]:.0f}-{high[0]:.0f}, right {low[1]:.0f}-{high[1]:.0f} deg")
    rows, traces = [], []
    for cap in [*args.caps, None]:  # None: the cleanup off
        if cap is not None:
            cleanup.PIVOT_TURN = cap
        result = generate(model, frames, SamplingOptions(count=args.samples, seed=0, cleanup=cap is not None))
        bends = [toe_bends(animation_from_bvh(c)) for c in result.clips]
        every = np.concatenate(bends)
        outside = ((every < low - MARGIN) | (every > high + MARGIN)).mean(axis=0)
        row = {"cap_radians": cap, "cleanup": cap is not None, "max": every.max(axis=0).round(1).tolist(),
               "min": every.min(axis=0).round(1).tolist(), "outside_share": outside.round(3).tolist(),
               "foot_skating_cm_s": round(plausibility(reference_bvh, result.clips)["aggregate"]["foot_skating_cm_s"], 2)}
        rows.append(row)
        traces.append((cap, bends[0][:, 0]))
        label = "cleanup off" if cap is None else f"toe aim capped at {cap:g} rad"
        print(f"{label}: max {row['max']}, min {row['min']}, frames more than {MARGIN:g} deg outside the clip's range "
              f"{[round(100 * s, 1) for s in row['outside_share']]} %, foot skating {row['foot_skating_cm_s']} cm/s", flush=True)
    if args.figure:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(10, 3.5))
        ax.axhspan(low[0], high[0], color="0.85", label=f"the clip's range ({low[0]:.0f}-{high[0]:.0f} deg)")
        for cap, trace in traces:
            label = "no cleanup" if cap is None else ("cleanup, toe aim uncapped" if np.isinf(cap) else f"cleanup, toe aim capped at {np.degrees(cap):.0f} deg")
            ax.plot(trace, lw=0.8, label=f"{label} (max {trace.max():.0f})")
        ax.set_xlabel("frame")
        ax.set_ylabel("left toe bend (deg)")
        ax.set_title(f"{args.clip.stem} model, sample seed 0: angle between the foot bone and the toe bone")
        ax.legend(fontsize=8, loc="upper right")
        fig.tight_layout()
        fig.savefig(args.figure, dpi=80)
    if args.results:
        args.results.write_text(json.dumps({"model": str(args.model), "clip": args.clip.name, "samples": args.samples, "frames": frames,
                                            "clip_range": [low.round(1).tolist(), high.round(1).tolist()],
                                            "rows": rows}, indent=2) + "\n")


if __name__ == "__main__":
    main()
