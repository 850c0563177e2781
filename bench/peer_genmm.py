"""Peer benchmark: GenMM (Li et al. 2023, generative motion matching, no training) beside
sinmdm in the same run, on a shared Mixamo clip and the crab.

    python bench/peer_genmm.py --genmm /work/peer/GenMM --work runs/peer \
        --results bench/results/peer_genmm.json

GenMM is the authors' public code (github.com/wyysf-98/GenMM), fetched separately and
never vendored: ``git clone https://github.com/wyysf-98/GenMM /work/peer/GenMM`` and
``pip install unfoldNd tqdm pyyaml`` (its pure-torch path; torch-scatter is not needed).
Check out fae65cd (2024-06-04, the authors' last change): later community commits make
``GenMM.match_and_blend`` read ``GenMM.KEYFRAME_INDICES``, which nothing defines.
It runs in-process on CPU with the settings of its own ``configs/ganimator.yaml``
(the skeleton configuration is its ``mixamo`` for the Mixamo clip and its
``crab_dance`` for the crab).

Per clip, both systems make motions of twice the clip's length (the paper's protocol):
one warm-up each, then ``--samples`` timed motions per system, called interleaved
(GenMM, sinmdm, GenMM, sinmdm, ...; seeds 0, 1, ...), torch and onnxruntime pinned to
``--threads``. The headline seconds are the median of the first ``--repeats`` timed
motions; every time is kept. All the timed motions are then scored with sinmdm's own
evaluator (the paper's metrics and the plausibility aggregate).

Timed (the headline): the generation, from a loaded exemplar/model to the motion in
memory (GenMM: ``GenMM.run``, its seed, matcher and pyramid included; sinmdm:
``generate``, decoding to BVH values included). Beside it, ``to_file``: the same plus
each system's own BVH writer (GenMM's ``BVHMotion.write``, a slow string builder;
sinmdm's ``write_outputs``). Not timed: GenMM's exemplar loading (once per clip, like
sinmdm's model loading) and the conversion below.

GenMM writes its reduced skeleton (the configuration's joints, namespaces cut), with
``Frame Time: 1`` and XYZ Euler angles. Each file is converted, outside the timing, to
the clip's own skeleton: the generated local rotations and root position of every
joint GenMM kept, on the clip's offsets and channel orders, at GenMM's real frame rate
(30 fps). Joints GenMM drops (the Mixamo fingers and HeadTop_End) hold the clip's
first-frame pose. The conversion checks that the kept joints have the clip's offsets
and parents, so the motion is unchanged.

sinmdm: a model exported from ``sinmdm train CLIP --preset cpu --out RUN`` and
``sinmdm export RUN --out RUN/model.onnx`` (``--sinmdm-model CLIP=PATH`` to give one;
else it is trained and exported into ``--work``), sampled at the model's defaults.
For reference the bundled demo model's 300-frame latency and 742-frame time are
measured in the same run.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import shlex
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
MOTIONS = ROOT.parent / "shared" / "motions"
CLIPS = ("Joe_Walk-In-Circle.bvh", "Crabnew_Crab-dance-long.bvh")
# GenMM's own skeleton configurations (dataset/bvh_motion.py skeleton_confs) per clip.
GENMM_SKELETON = {"Joe_": "mixamo", "Crabnew_": "crab_dance"}
GENMM_URL = "https://github.com/wyysf-98/GenMM"
sys.path.insert(0, str(ROOT))


def fail(message: str) -> None:
    print(f"peer_genmm: {message}", file=sys.stderr)
    raise SystemExit(2)


def machine() -> dict:
    info = {"platform": platform.platform(), "python": platform.python_version()}
    try:
        text = subprocess.run(["lscpu"], capture_output=True, text=True, check=True).stdout
        fields = dict(line.split(":", 1) for line in text.splitlines() if ":" in line)
        info["cpu"] = fields.get("Model name", "").strip()
        info["cpus"] = int(fields.get("CPU(s)", "0").strip() or 0)
        cores = fields.get("Core(s) per socket", "").strip()
        sockets = fields.get("Socket(s)", "1").strip()
        if cores:
            info["cores"] = int(cores) * int(sockets or 1)
    except (OSError, subprocess.CalledProcessError, ValueError):
        info["cpu"] = platform.processor()
        info["cpus"] = os.cpu_count()
    return info


# --------------------------------------------------------------------------- GenMM


class Peer:
    """GenMM loaded from its checkout, run as its run_random_generation.py does."""

    def __init__(self, path: Path, threads: int):
        if not (path / "GenMM.py").is_file() or not (path / "configs" / "ganimator.yaml").is_file():
            fail(f"no GenMM checkout at {path}: fetch it with `git clone {GENMM_URL} {path}` "
                 "(never vendored) and give its path with --genmm")
        os.environ.setdefault("TQDM_DISABLE", "1")  # its progress bar, not its work
        sys.path.insert(0, str(path))
        try:
            import torch
            import yaml
            from GenMM import GenMM
            from dataset.bvh_motion import BVHMotion
            from nearest_neighbor.losses import PatchCoherentLoss
            from utils.base import set_seed
        except ImportError as exc:
            fail(f"cannot import GenMM from {path} ({exc}); install its CPU needs: pip install unfoldNd tqdm pyyaml")
        torch.set_num_threads(threads)
        self.torch, self.GenMM, self.BVHMotion, self.Loss, self.set_seed = torch, GenMM, BVHMotion, PatchCoherentLoss, set_seed
        self.path = path
        self.config = yaml.safe_load((path / "configs" / "ganimator.yaml").read_text())
        self.commit = _git_commit(path)

    def skeleton_for(self, clip: str) -> str:
        for prefix, name in GENMM_SKELETON.items():
            if clip.startswith(prefix):
                return name
        return self.config["skeleton_name"]

    def load(self, clip_path: Path):
        c = self.config
        return self.BVHMotion(str(clip_path), skeleton_name=self.skeleton_for(clip_path.name), repr=c["repr"],
                              use_velo=c["use_velo"], keep_up_pos=c["keep_up_pos"], up_axis=c["up_axis"],
                              padding_last=c["padding_last"], requires_contact=c["requires_contact"],
                              joint_reduction=c["joint_reduction"])

    def settings(self, clip: str) -> dict:
        keys = ("repr", "use_velo", "keep_up_pos", "up_axis", "padding_last", "requires_contact", "joint_reduction",
                "num_frames", "alpha", "num_steps", "noise_sigma", "coarse_ratio", "pyr_factor", "patch_size", "loop")
        return {"config": "configs/ganimator.yaml", "skeleton_name": self.skeleton_for(clip), "device": "cpu",
                **{k: self.config[k] for k in keys}}

    def generate(self, motion, seed: int, out: Path) -> tuple[float, float, object]:
        """One motion into `out` (GenMM's writer); (seconds to the file, seconds of GenMM.run,
        the generated tensor)."""
        c = self.config
        began = time.perf_counter()
        self.set_seed(seed)
        model = self.GenMM(device="cpu", silent=True)
        criteria = self.Loss(patch_size=c["patch_size"], alpha=c["alpha"], loop=c["loop"], cache=True)
        syn = model.run([motion], criteria, num_frames=str(c["num_frames"]), num_steps=c["num_steps"],
                        noise_sigma=c["noise_sigma"], patch_size=c["patch_size"], coarse_ratio=c["coarse_ratio"],
                        pyr_factor=c["pyr_factor"])
        ran = time.perf_counter() - began
        self.write(motion, syn, out)
        return time.perf_counter() - began, ran, syn

    @staticmethod
    def write(motion, syn, out: Path, as_is: bool = False) -> None:
        """GenMM's own writer, fed so that its output is the generated motion.

        Its `BVHMotion.write` drops the padding channels (`padding_last`, on in the
        GANimator config) before integrating the root velocity, but the velocity channel
        indices count that padding, so it integrates two root-rotation channels and writes
        the root's per-frame displacement as its position. Here the velocities are
        integrated first, on the padded tensor as stored (`MotionData.to_position`), and the
        writer is told the data already holds positions. `to_position` also forgets the
        start position after one call (one write per loaded exemplar); it is kept for the
        next motion. `as_is=True` calls the writer unchanged (for the record).
        """
        data = motion.motion_data
        begin = data.begin_pos.clone()
        try:
            if as_is:
                motion.write(str(out), syn)
            else:
                positions = data.to_position(syn)
                data.use_velo = False
                motion.write(str(out), positions)
        finally:
            data.use_velo = True
            data.begin_pos = begin


def _git_commit(path: Path) -> str | None:
    try:
        return subprocess.run(["git", "-C", str(path), "rev-parse", "HEAD"], capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None


def _bare(name: str) -> str:
    return name.split(":", 1)[1] if ":" in name else name


def to_clip_skeleton(genmm_path: Path, clip, fps: float, out: Path) -> dict:
    """Rewrite GenMM's BVH on the clip's skeleton (see the module docstring); what was filled in."""
    from sinmdm.runtime import read_bvh, write_bvh
    from sinmdm.runtime.animation import Animation, animation_from_bvh, animation_to_bvh

    peer = animation_from_bvh(read_bvh(genmm_path))
    ref = animation_from_bvh(clip)
    ps, rs = peer.skeleton, clip.skeleton
    where = {_bare(n): j for j, n in enumerate(ps.names)}
    kept = [j for j, n in enumerate(rs.names) if _bare(n) in where]
    if len(kept) != len(ps.names):
        raise ValueError(f"{genmm_path.name}: {len(ps.names) - len(kept)} GenMM joints are not in the clip")
    for j in kept:
        p = where[_bare(rs.names[j])]
        parent_ok = (rs.parents[j] < 0 and ps.parents[p] < 0) or (
            rs.parents[j] >= 0 and ps.parents[p] >= 0
            and _bare(rs.names[rs.parents[j]]) == _bare(ps.names[ps.parents[p]]))
        if not parent_ok or not np.allclose(rs.offsets[j], ps.offsets[p], atol=1e-4 * max(1.0, np.abs(rs.offsets[j]).max())):
            raise ValueError(f"{genmm_path.name}: joint {rs.names[j]} has another parent or offset than in the clip")
    frames = peer.frames
    rotations = np.broadcast_to(ref.rotations[0], (frames, *ref.rotations.shape[1:])).copy()
    translations = np.broadcast_to(rs.offsets, (frames, rs.num_joints, 3)).copy()
    for j in kept:
        rotations[:, j] = peer.rotations[:, where[_bare(rs.names[j])]]
    root = rs.roots[0]
    translations[:, root] = peer.translations[:, where[_bare(rs.names[root])]]
    write_bvh(out, animation_to_bvh(Animation(rs, rotations, translations, fps)))
    return {"joints_generated": len(kept), "joints_held_at_clip_frame_0": rs.num_joints - len(kept)}


# --------------------------------------------------------------------------- sinmdm


def sinmdm_model(clip_name: str, given: dict[str, Path], work: Path) -> Path:
    from bench.quality import export_trained_window, run

    if clip_name in given:
        return given[clip_name]
    run_dir = work / Path(clip_name).stem
    config_path = run_dir / "config.json"
    config = json.loads(config_path.read_text()) if config_path.exists() else {}
    if not config.get("finished"):
        resume = ["--resume"] if config_path.exists() else []
        run("sinmdm", "train", str(MOTIONS / clip_name), "--preset", "cpu", "--out", str(run_dir), *resume)
        config = json.loads(config_path.read_text())
    model = run_dir / f"model_w{config['window']}.onnx"
    return model if model.exists() else export_trained_window(run_dir, config["window"])


class Ours:
    def __init__(self, model_path: Path, threads: int):
        from sinmdm.runtime import load_model

        self.path = model_path
        self.model = load_model(model_path, threads=threads)

    def generate(self, frames: int, seed: int, out_dir: Path) -> tuple[float, float, Path | None]:
        from sinmdm.runtime import SamplingOptions, generate, write_outputs

        began = time.perf_counter()
        result = generate(self.model, frames, SamplingOptions(count=1, seed=seed))
        ran = time.perf_counter() - began
        paths = write_outputs(self.model, result, out_dir, name="sinmdm", force=True) if out_dir else [None]
        return time.perf_counter() - began, ran, paths[0]


# --------------------------------------------------------------------------- scoring


def score(clip: Path, paths: list[Path], preset: str) -> dict:
    from sinmdm.eval.motion_features import evaluate_files

    scores = evaluate_files(clip, paths, preset=preset)
    keys = ("coverage", "global_diversity", "local_diversity", "inter_diversity", "intra_diversity_diff")
    plaus = scores.get("plausibility") or {}
    return {**{k: scores[k] for k in keys}, "samples": scores["samples"], "sample_frames": scores["sample_frames"],
            "eval_preset": preset, "plausibility": plaus.get("aggregate"),
            "verdicts": [s["verdict"] for s in plaus.get("samples", [])]}


def timing(runs: list[float], repeats: int) -> dict:
    head = runs[:repeats]
    return {"seconds_median": round(statistics.median(head), 3), "timed_runs_in_median": len(head),
            "seconds_median_all": round(statistics.median(runs), 3), "seconds_all": [round(t, 3) for t in runs]}


def bench_clip(name: str, peer: Peer, ours: Ours, args, out: Path) -> dict:
    from bench.quality import eval_protocol
    from sinmdm.runtime import read_bvh

    clip_path = MOTIONS / name
    clip = read_bvh(clip_path)
    # the paper's protocol: twice the clip's length at the model's frame rate (as bench/quality.py)
    frames = 2 * round(clip.frames / clip.fps * ours.model.codec.fps)
    began = time.perf_counter()
    motion = peer.load(clip_path)
    peer_load = time.perf_counter() - began
    peer_fps = 1.0 / motion.raw_data.frametime
    peer_fps = float(round(peer_fps)) if abs(peer_fps - round(peer_fps)) < 1e-2 else peer_fps
    raw_dir, peer_dir, ours_dir = out / "genmm_raw", out / "genmm", out / "sinmdm"
    for d in (raw_dir, peer_dir, ours_dir):
        d.mkdir(parents=True, exist_ok=True)
    warm = 10_000
    peer.generate(motion, warm, raw_dir / "warmup.bvh")
    ours.generate(frames, warm, None)
    t = {"genmm": [], "genmm_run": [], "sinmdm": [], "sinmdm_generate": []}
    peer_paths, ours_paths, kept = [], [], []
    for seed in range(args.samples):
        raw = raw_dir / f"genmm_{seed:04d}.bvh"
        total, ran, syn = peer.generate(motion, seed, raw)
        if seed < args.as_is_samples:
            kept.append(syn)
        t["genmm"].append(total)
        t["genmm_run"].append(ran)
        total, ran, path = ours.generate(frames, seed, ours_dir)
        t["sinmdm"].append(total)
        t["sinmdm_generate"].append(ran)
        ours_paths.append(path)
        print(f"{name} seed {seed}: GenMM {t['genmm_run'][-1]:.2f}s ({t['genmm'][-1]:.2f}s to file) "
              f"sinmdm {t['sinmdm_generate'][-1]:.2f}s ({t['sinmdm'][-1]:.2f}s to file)", flush=True)
    conversion = None
    for seed in range(args.samples):
        raw = raw_dir / f"genmm_{seed:04d}.bvh"
        peer_paths.append(peer_dir / raw.name)
        conversion = to_clip_skeleton(raw, clip, peer_fps, peer_paths[-1])
    # For the record: GenMM's writer called unchanged on the first motions (see Peer.write).
    as_is_paths = []
    if args.as_is_samples:
        (out / "genmm_as_is_raw").mkdir(exist_ok=True)
        (out / "genmm_as_is").mkdir(exist_ok=True)
    for seed, syn in enumerate(kept):  # the same generated motions, only the writing differs
        raw = out / "genmm_as_is_raw" / f"genmm_{seed:04d}.bvh"
        peer.write(motion, syn, raw, as_is=True)
        as_is_paths.append(out / "genmm_as_is" / raw.name)
        to_clip_skeleton(raw, clip, peer_fps, as_is_paths[-1])
    preset = eval_protocol(name)
    peer_frames = read_bvh(peer_paths[0]).frames
    return {
        "clip": name, "clip_frames": clip.frames, "clip_fps": clip.fps, "eval_preset": preset,
        "genmm": {"frames": peer_frames, "fps": peer_fps, "settings": peer.settings(name),
                  "exemplar_load_seconds": round(peer_load, 3),
                  **timing(t["genmm_run"], args.repeats), "to_file": timing(t["genmm"], args.repeats),
                  "conversion": conversion, "quality": score(clip_path, peer_paths, preset),
                  "quality_as_is_writer": score(clip_path, as_is_paths, preset) if as_is_paths else None},
        "sinmdm": {"frames": frames, "fps": ours.model.codec.fps, "model": _rel(ours.path),
                   "training": training_record(ours.path),
                   "steps": ours.model.default_steps, "hop": ours.model.default_hop(frames),
                   **timing(t["sinmdm_generate"], args.repeats), "to_file": timing(t["sinmdm"], args.repeats),
                   "quality": score(clip_path, ours_paths, preset)},
        "ratio_sinmdm_over_genmm": round(statistics.median(t["sinmdm_generate"][:args.repeats])
                                         / statistics.median(t["genmm_run"][:args.repeats]), 2),
        "ratio_to_file": round(statistics.median(t["sinmdm"][:args.repeats])
                               / statistics.median(t["genmm"][:args.repeats]), 2),
    }


def training_record(model_path: Path) -> dict | None:
    """The run a model was exported from, when it lies beside it (trained by this script)."""
    config_path = Path(model_path).parent / "config.json"
    if not config_path.exists():
        return None
    config = json.loads(config_path.read_text())
    watch = config.get("watch") or {}
    return {"run": _rel(config_path.parent), "preset": config["train"]["preset"], "step": config["step"],
            "steps": config["steps"], "finished": config["finished"], "elapsed_seconds": config.get("elapsed_seconds"),
            "stopped": watch.get("stopped"), "stage": config.get("stage"), "sampling": config.get("sampling")}


def demo_reference(threads: int, repeats: int) -> dict:
    """The bundled demo model's 300-frame latency and 742-frame time, interleaved."""
    from sinmdm.runtime.model import DEMO_MODEL

    demo = Ours(Path(DEMO_MODEL), threads)
    lengths = (300, 742)
    for n in lengths:
        demo.generate(n, 10_000, None)
    runs = {n: [] for n in lengths}
    for seed in range(repeats):
        for n in lengths:
            runs[n].append(demo.generate(n, seed, None)[1])
    return {"model": _rel(Path(DEMO_MODEL)), "steps": demo.model.default_steps,
            **{f"frames_{n}": timing(runs[n], repeats) for n in lengths}}


def commands(clips: list[dict], genmm: Path) -> list[str]:
    """How the peer and each sinmdm model were obtained (from the runs' own records)."""
    from sinmdm.train.presets import PRESETS

    done = [f"git clone {GENMM_URL} {genmm}  # checked out at the commit recorded under genmm",
            "pip install unfoldNd tqdm pyyaml  # GenMM's CPU needs (torch kept)"]
    for clip in clips:
        record = clip["sinmdm"]["training"]
        if record is None:
            done.append(f"# {clip['clip']}: sinmdm model given with --sinmdm-model {clip['sinmdm']['model']}")
            continue
        run_dir, source = record["run"], f"../shared/motions/{clip['clip']}"
        done.append(f"sinmdm train {source} --preset {record['preset']} --out {run_dir}")
        if record["steps"] != PRESETS[record["preset"]].steps:
            done.append(f"sinmdm train {source} --preset {record['preset']} --out {run_dir} --resume --steps {record['steps']}")
        done.append(f"sinmdm export {run_dir} --out {run_dir}/model.onnx --force")
    return done


def _rel(path: Path) -> str:
    try:
        return str(Path(path).resolve().relative_to(ROOT))
    except ValueError:
        return str(path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--genmm", type=Path, default=Path("/work/peer/GenMM"), help="GenMM checkout (fetched separately)")
    parser.add_argument("--clips", nargs="+", default=list(CLIPS))
    parser.add_argument("--sinmdm-model", action="append", default=[], metavar="CLIP=PATH",
                        help="an exported sinmdm model for a clip (else trained and exported into --work)")
    parser.add_argument("--work", type=Path, default=ROOT / "runs" / "peer")
    parser.add_argument("--samples", type=int, default=20, help="timed and scored motions per system per clip")
    parser.add_argument("--repeats", type=int, default=5, help="timed motions in the headline median")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--as-is-samples", type=int, default=5,
                        help="GenMM motions also written by its writer unchanged and scored (not timed)")
    parser.add_argument("--results", type=Path, default=ROOT / "bench" / "results" / "peer_genmm.json")
    parser.add_argument("--note", default="", help="added to the results (e.g. machine load)")
    args = parser.parse_args()
    if args.samples < args.repeats:
        fail("--samples must be at least --repeats")
    given = {}
    for item in args.sinmdm_model:
        clip, sep, path = item.partition("=")
        if not sep:
            fail(f"--sinmdm-model wants CLIP=PATH, got {item!r}")
        given[clip] = Path(path)
    os.environ.setdefault("OMP_NUM_THREADS", str(args.threads))
    peer = Peer(args.genmm, args.threads)  # first: a missing checkout stops before any training
    models = {name: sinmdm_model(name, given, args.work) for name in args.clips}
    began = time.perf_counter()
    clips = []
    for name in args.clips:
        ours = Ours(models[name], args.threads)
        clips.append(bench_clip(name, peer, ours, args, args.work / "samples" / Path(name).stem))
        print(json.dumps({k: clips[-1][k] for k in ("clip", "ratio_sinmdm_over_genmm")}), flush=True)
    demo = demo_reference(args.threads, args.repeats)
    result = {
        "benchmark": "peer_genmm",
        "date": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
        "machine": machine(),
        "threads": args.threads,
        "command": shlex.join(["python", _rel(Path(sys.argv[0])), *sys.argv[1:]]),
        "commands": commands(clips, args.genmm),
        "note": args.note,
        "genmm": {"source": GENMM_URL, "path": str(args.genmm), "commit": peer.commit, "torch": peer.torch.__version__},
        "protocol": ("per clip: one warm-up each, then seeds 0..samples-1 interleaved GenMM, sinmdm; "
                     "seconds_median = median of the first `repeats` timed generations (to_file: with each "
                     "system's BVH writer); "
                     "all timed motions scored with sinmdm.eval.motion_features.evaluate_files"),
        "clips": clips,
        "demo_reference": demo,
        "wall_seconds": round(time.perf_counter() - began, 1),
    }
    args.results.parent.mkdir(parents=True, exist_ok=True)
    args.results.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.results}")


if __name__ == "__main__":
    main()
