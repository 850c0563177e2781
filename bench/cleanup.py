"""Foot-contact cleanup: foot skating and the paper's metrics with the cleanup off and on.

    python bench/cleanup.py                                   # the bundled demo model
    python bench/cleanup.py --model runs/x/model_w64.onnx --clip clip.bvh --protocol mixamo24
    python bench/cleanup.py --figure docs/cleanup_feet.png    # also draw one sample's feet

Same model, same seeds, same edge margin; only `cleanup` differs. Foot skating is
the plausibility metric (mean horizontal speed of the contact joints on frames where
they are slow and near the clip's floor, cm/s), against the training clip's own.
A second seed set gives the run-to-run spread of coverage and diversity, the yardstick
for "the paper's metrics do not move".
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from sinmdm.eval import metrics
from sinmdm.eval.motion_features import eval_features, evaluate_files, protocol_for
from sinmdm.runtime import SamplingOptions, generate, load_model, read_bvh, write_outputs
from sinmdm.runtime.animation import animation_from_bvh, global_positions
from sinmdm.runtime.model import DEMO_MODEL

KEYS = ("coverage", "global_diversity", "local_diversity")


def contact_split(clip: Path, samples: list, protocol: str) -> dict:
    """What the paper's diversity reads: the share of frames whose contact bit is set
    (samples against the clip), and the metrics on the rotation columns alone."""
    reference = read_bvh(clip)
    chosen = protocol_for(reference, protocol, None)
    ref = eval_features(reference, chosen)
    own = [eval_features(s, chosen) for s in samples]
    contacts = len(chosen.contact_joints)
    rotations = metrics.evaluate(ref[:, : ref.shape[1] - contacts], [f[:, : f.shape[1] - contacts] for f in own], seed=0)
    return {"contact_share": np.concatenate(own)[:, ref.shape[1] - contacts :].mean(axis=0).round(3).tolist(),
            "clip_contact_share": ref[:, ref.shape[1] - contacts :].mean(axis=0).round(3).tolist(),
            "rotations_only": {k: rotations[k] for k in KEYS}}


def measure(model, clip: Path, frames: int, count: int, seed: int, cleanup: bool, protocol: str) -> tuple[dict, list]:
    result = generate(model, frames, SamplingOptions(count=count, seed=seed, cleanup=cleanup))
    with tempfile.TemporaryDirectory() as tmp:
        paths = write_outputs(model, result, Path(tmp), force=True)
        scores = evaluate_files(clip, paths, preset=protocol)
    aggregate = scores["plausibility"]["aggregate"]
    return {**{k: scores[k] for k in KEYS}, **contact_split(clip, result.clips, protocol),
            "foot_skating_cm_s": aggregate["foot_skating_cm_s"],
            "clip_foot_skating_cm_s": aggregate["clip_foot_skating_cm_s"],
            "foot_bob_cm_s": aggregate["foot_bob_cm_s"], "clip_foot_bob_cm_s": aggregate["clip_foot_bob_cm_s"],
            "penetration_cm": aggregate["penetration_cm"], "penetration_share": aggregate["penetration_share"],
            "per_sample_skating_cm_s": [r["foot_skating_cm_s"] for r in scores["plausibility"]["samples"]],
            "implausible": aggregate["implausible"]}, result.clips


def figure(model, before, after, path: Path) -> None:
    """Top view and speed of one contact joint of the first sample, cleanup off and on."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    codec = model.codec
    joint = codec.contact_joints[0]
    h1, h2 = codec.horizontal_axes
    fig, (top, speed) = plt.subplots(1, 2, figsize=(11, 4))
    shown = slice(0, min(int(6 * codec.fps), before.frames))  # 6 s: the steps stay readable
    for clip, label, style in ((before, "cleanup off", "C3"), (after, "cleanup on (default)", "C0")):
        p = global_positions(animation_from_bvh(clip))[shown, joint] * codec.scale
        top.plot(p[:, h1], p[:, h2], style, lw=1, marker=".", ms=3, label=label)
        v = np.linalg.norm(np.diff(p[:, [h1, h2]], axis=0), axis=-1) * codec.fps * 100
        speed.plot(np.arange(1, len(p)) / codec.fps, v, style, lw=1, label=label)
    name = codec.skeleton.names[joint]
    top.set_title(f"{name}: path seen from above, first 6 s (m; dots = frames)")
    top.set_aspect("equal", adjustable="datalim")
    speed.set_title(f"{name}: horizontal speed (cm/s); flat at 0 = planted")
    speed.set_xlabel("s")
    speed.set_ylim(0, 120)
    speed.legend(loc="upper right")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, default=DEMO_MODEL)
    parser.add_argument("--clip", type=Path, default=DEMO_MODEL.with_name("stomper.bvh"))
    parser.add_argument("--protocol", default="default")
    parser.add_argument("--samples", type=int, default=8)
    parser.add_argument("--seconds", type=float, default=None, help="default: twice the clip")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1000])
    parser.add_argument("--figure", type=Path, default=None)
    parser.add_argument("--results", type=Path, default=None, help="append the row to this JSON list")
    args = parser.parse_args()

    model = load_model(args.model)
    reference = read_bvh(args.clip)
    seconds = args.seconds or 2 * reference.frames * reference.frame_time
    frames = round(seconds * model.codec.fps)
    row = {"model": str(args.model), "clip": args.clip.name, "protocol": args.protocol, "samples": args.samples,
           "frames": frames, "date": time.strftime("%Y-%m-%d"), "runs": {}}
    for seed in args.seeds:
        for cleanup in (False, True):
            scores, clips = measure(model, args.clip, frames, args.samples, seed, cleanup, args.protocol)
            row["runs"][f"{'on' if cleanup else 'off'}@{seed}"] = scores
            if args.figure and seed == args.seeds[0]:
                if cleanup:
                    figure(model, first_off, clips[0], args.figure)
                else:
                    first_off = clips[0]
            print(f"seed {seed} cleanup {'on ' if cleanup else 'off'}: skating {scores['foot_skating_cm_s']:.2f} cm/s "
                  f"(clip {scores['clip_foot_skating_cm_s']:.2f}), bobbing {scores['foot_bob_cm_s']:.2f} cm/s "
                  f"(clip {scores['clip_foot_bob_cm_s']:.2f}), coverage {scores['coverage']:.1f}, "
                  f"global {scores['global_diversity']:.3f}, local {scores['local_diversity']:.3f}; contact bits set on "
                  f"{scores['contact_share']} of frames (clip {scores['clip_contact_share']}); rotations only: global "
                  f"{scores['rotations_only']['global_diversity']:.3f}, local {scores['rotations_only']['local_diversity']:.3f}",
                  flush=True)
    if args.results:
        rows = json.loads(args.results.read_text()) if args.results.exists() else []
        rows = [r for r in rows if (r["model"], r["clip"]) != (row["model"], row["clip"])] + [row]
        args.results.parent.mkdir(parents=True, exist_ok=True)
        args.results.write_text(json.dumps(rows, indent=2) + "\n")


if __name__ == "__main__":
    main()
