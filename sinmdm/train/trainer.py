"""The training loop: one clip in, a durable, resumable run directory out."""

from __future__ import annotations

import copy
import json
import math
import time
from dataclasses import dataclass, replace
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from .. import __version__
from ..eval.balance import CheckSettings
from ..runtime.atomic import check_writable_dir, file_sha256, write_text_atomic
from ..runtime.bvh import BVH, read_bvh
from ..runtime.errors import SinMDMError
from ..runtime.features import MotionCodec, build_codec
from ..runtime.graph_space import graph_space
from ..runtime.heading import ROOT_FRAMES, HeadingFrame, clip_heading_frame, trajectory_rotation
from ..runtime.schedule import NUM_TIMESTEPS, cosine_alphas_cumprod
from .checkpoint import (BEST, CHECKSUMS, CONFIG, LOG, RUN_FORMAT, STAGE_PREFIX, load_best, load_config,
                         load_state, log_records, nonfinite_tensor, save_run)
from .compiled import COMPILE_CHOICES, Forward, training_forward
from .data import BatchSampler
from .diffusion import GaussianDiffusion, loss_weighting
from .foot_loss import FootContactLoss
from .model import Denoiser, ModelConfig, count_parameters, receptive_field
from .presets import TrainConfig
from .watch import COPYING, PEAKED, STALLED, QualityWatch, WatchState, sampling_defaults, stop_reason


def resolve_device(name: str = "auto") -> torch.device:
    """`auto` picks CUDA, then Apple's MPS, then the CPU."""
    if name == "auto":
        if torch.cuda.is_available():
            return torch.device("cuda")
        if getattr(torch.backends, "mps", None) is not None and torch.backends.mps.is_available():
            return torch.device("mps")
        return torch.device("cpu")
    try:
        device = torch.device(name)
    except RuntimeError:
        raise SinMDMError(f"unknown device '{name}': use auto, cpu, cuda or mps") from None
    if device.type == "cuda" and not torch.cuda.is_available():
        raise SinMDMError("--device cuda requested but no CUDA GPU is available")
    return device


def bf16_supported(device: torch.device) -> bool:
    if device.type == "cuda":
        return torch.cuda.is_bf16_supported()
    if device.type == "cpu":
        return bool(torch.ops.mkldnn._is_mkldnn_bf16_supported())
    return False


def learning_rate_factor(config: TrainConfig) -> Callable[[int], float]:
    if config.lr_schedule == "exponential":
        return lambda step: config.lr_gamma**step
    if config.lr_schedule == "linear-tail":
        decay_start = (1.0 - config.lr_tail) * config.steps
        return lambda step: 1.0 if step < decay_start else max(0.0, (config.steps - step) / max(config.steps - decay_start, 1))
    if config.lr_schedule == "constant":
        return lambda step: 1.0
    raise SinMDMError(f"unknown learning-rate schedule '{config.lr_schedule}'")


@dataclass
class ClipData:
    codec: MotionCodec
    features: np.ndarray  # (T, F)
    start: np.ndarray  # (x, z) of the trajectory joint at frame 0, metres
    info: dict
    bvh: BVH


ROOT_FRAME_CHOICES = ROOT_FRAMES + ("auto",)
# A clip whose heading turns faster than this on average (its net turn over its length) is
# trained in the heading frame by `auto`: a world-frame model of the walk in a circle (29 deg/s)
# never turned, in one window or at the joins, and spun where windows met; in the heading frame
# it walked circles. Clips that turn back and forth or barely (crab 1.9, idle 0.1, Xia 1-3, the
# elephant 0 deg/s) keep the world frame: in the heading frame the crab's samples covered 69 % of
# the clip against 84 %, the idle's drifted round at 17.5 deg/s and shook, Xia proud lost 0.17 of
# global diversity (BENCHMARKS.md, "Turning, spins and the heading frame").
AUTO_HEADING_DEG_S = 10.0


def choose_root_frame(clip: ClipData, config: TrainConfig, heading: HeadingFrame | None) -> tuple[str, str]:
    """(frame, why) for `config.root_frame` on this clip; `heading`: the clip's heading frame,
    None where its trajectory joint has no rotation."""
    if config.root_frame not in ROOT_FRAME_CHOICES:
        raise SinMDMError(f"unknown root frame {config.root_frame!r}: use {', '.join(ROOT_FRAME_CHOICES)}")
    if config.root_frame == "heading":
        if heading is None:
            raise SinMDMError("--root-frame heading needs a trajectory joint with rotation channels; this clip has none")
    if config.root_frame != "auto":
        return config.root_frame, "asked for"
    if heading is None:
        return "world", "auto: the clip has no trajectory joint with rotation channels"
    headings = heading.headings(np.asarray(clip.features, dtype=np.float64))
    rate = float(np.degrees(headings[-1] - headings[0]) / max((len(headings) - 1) / clip.codec.fps, 1e-9))
    if abs(rate) > AUTO_HEADING_DEG_S:
        return "heading", f"auto: the clip turns {rate:+.1f} deg/s on average, more than {AUTO_HEADING_DEG_S:g}"
    return "world", f"auto: the clip turns {rate:+.1f} deg/s on average, not more than {AUTO_HEADING_DEG_S:g}"


def foot_loss_choice(codec, config: TrainConfig) -> tuple[bool, str]:
    """Whether the foot-contact loss trains this clip, and why. A clip without contact joints or
    a trajectory joint trains without it, as the paper's loss."""
    if config.foot_loss <= 0:
        return False, "off: the paper's loss alone"
    if codec.trajectory_joint is None or not codec.contact_joints:
        return False, "off: the clip has no contact joints or no trajectory joint to hold"
    what = "contact joints' velocity matched to the clip's" if config.foot_loss_target == "clip" else "planted joints held still"
    return True, f"on: weight {config.foot_loss:g}, the {what}"


def graph_metadata(clip: ClipData, config: TrainConfig) -> dict:
    """How the model's graph sees the clip's features (runtime.graph_space), as its metadata says
    it, and why its root frame was chosen."""
    turnable = config.root_frame != "world" and trajectory_rotation(clip.codec) is not None
    heading = clip_heading_frame(clip.codec, clip.features) if turnable else None
    frame, why = choose_root_frame(clip, config, heading)
    return {"velocity_unit": config.velocity_unit, "heading_frame": heading.to_dict() if frame == "heading" else None,
            "root_frame": {"frame": frame, "why": why}}


def load_clip(path: Path, fps: float, codec_options: dict) -> ClipData:
    bvh = read_bvh(path)
    codec = build_codec(bvh, fps=fps, **codec_options)
    features = codec.encode(bvh, source_fps=codec_options.get("source_fps"))
    if not np.isfinite(features).all():
        raise SinMDMError(f"{path}: the clip's features contain NaN or infinite values")
    info = {
        "name": Path(path).name,
        "sha256": file_sha256(path),
        "frames": int(features.shape[0]),
        "source_frames": bvh.frames,
        "source_fps": codec_options.get("source_fps") or bvh.fps,
    }
    start = codec.start_position(bvh, source_fps=codec_options.get("source_fps"))
    return ClipData(codec, features, start, info, bvh)


class Run:
    """Model, EMA, optimiser, schedule and RNG states of one training run."""

    def __init__(self, clip: ClipData, config: TrainConfig, seed: int, device: torch.device,
                 compile_mode: str = "auto"):
        self.clip, self.config, self.seed, self.device = clip, config, seed, device
        self.graph_metadata = graph_metadata(clip, config)  # what the exported model will say of its graph
        space = graph_space(clip.codec, self.graph_metadata)  # features -> the model's space
        self.model_config = ModelConfig(
            features=space.width, width=config.width, norm=config.norm, dropout=config.dropout
        )
        self.receptive_field = receptive_field(self.model_config)
        if clip.features.shape[0] < self.receptive_field:
            raise SinMDMError(
                f"clip has {clip.features.shape[0]} frames at {config.fps:g} fps, fewer than the "
                f"model's receptive field of {self.receptive_field} frames"
            )
        torch.manual_seed(seed)
        self.model = Denoiser(self.model_config).to(device)
        self.ema = copy.deepcopy(self.model).requires_grad_(False) if config.ema else None
        self.optimizer = torch.optim.AdamW(self.model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
        self.scheduler = torch.optim.lr_scheduler.LambdaLR(self.optimizer, learning_rate_factor(config))
        abar = cosine_alphas_cumprod()
        self.diffusion = GaussianDiffusion(abar, loss_weighting(config.loss_weighting, abar))
        self.generator = torch.Generator().manual_seed(seed)
        clip_tensor = torch.from_numpy(np.ascontiguousarray(space.to_graph(clip.features).T, dtype=np.float32))
        self.sampler = BatchSampler(clip_tensor, config, self.generator)
        foot_loss_on, self.foot_loss_why = foot_loss_choice(clip.codec, config)
        self.extra_loss = None
        if foot_loss_on:
            self.extra_loss = self._foot_term(FootContactLoss(clip.codec, space.scale, heading=space.heading is not None), config)
        self.step = 0
        self.watch = WatchState()
        self.stopped: str | None = None  # why the watch ended the run early
        self.sampling: dict | None = None  # sampling defaults measured on the kept weights
        self.loss = float("nan")
        self.elapsed = 0.0
        self.checksums: dict[str, str] = {}  # sha256 of the weights files the run's config names
        self.saved_step = 0
        self.autocast = config.bf16 and bf16_supported(device)
        self.compile_mode = compile_mode
        self.forward: Forward | None = None  # chosen at the first step (compiled.py)

    # ------------------------------------------------------------- state
    def _foot_term(self, foot: FootContactLoss, config: TrainConfig):
        weight = config.foot_loss
        if config.foot_loss_target == "still":
            return lambda prediction, x0, t: weight * foot(prediction, x0)
        abar = torch.as_tensor(self.diffusion.alphas_cumprod, dtype=torch.float32)
        return lambda prediction, x0, t: weight * foot(prediction, x0, abar.to(t.device)[t])

    def state(self) -> dict:
        state = {
            "step": self.step,
            "model": self.model.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "scheduler": self.scheduler.state_dict(),
            "torch_rng": torch.get_rng_state(),
            "data_rng": self.generator.get_state(),
            "loss": self.loss,
            "elapsed": self.elapsed,
            "watch": self.watch.to_dict(),
            "stopped": self.stopped,
            "sampling": self.sampling,
        }
        if self.ema is not None:
            state["ema"] = self.ema.state_dict()
        if self.device.type == "cuda":
            state["cuda_rng"] = torch.cuda.get_rng_state()
        return state

    def load_state(self, state: dict) -> None:
        try:
            self.model.load_state_dict(state["model"])
            if self.ema is not None:
                self.ema.load_state_dict(state["ema"])
            self.optimizer.load_state_dict(state["optimizer"])
            self.scheduler.load_state_dict(state["scheduler"])
            torch.set_rng_state(state["torch_rng"])
            self.generator.set_state(state["data_rng"])
            if self.device.type == "cuda" and "cuda_rng" in state:
                torch.cuda.set_rng_state(state["cuda_rng"])
        except (KeyError, RuntimeError, ValueError) as exc:
            raise SinMDMError(f"checkpoint does not match this run's model ({type(exc).__name__}: {str(exc)[:120]})") from None
        self.step = int(state["step"])
        self.loss = float(state.get("loss", float("nan")))
        self.elapsed = float(state.get("elapsed", 0.0))
        self.watch = WatchState.from_dict(state.get("watch"))
        self.stopped = state.get("stopped")
        self.sampling = state.get("sampling")

    def nonfinite_weight(self) -> str | None:
        modules = [self.model] + ([self.ema] if self.ema is not None else [])
        return next(filter(None, (nonfinite_tensor(m.state_dict()) for m in modules)), None)

    def diverged(self, what: str) -> SinMDMError:
        return SinMDMError(f"training diverged at step {self.step}: {what}; the last good checkpoint "
                           f"(step {self.saved_step}) is kept")

    @property
    def finished(self) -> bool:
        return self.step >= self.config.steps or self.stopped is not None

    def config_dict(self, finished: bool) -> dict:
        return {
            "run_format": RUN_FORMAT,
            "sinmdm_version": __version__,
            "clip": self.clip.info,
            "codec": self.clip.codec.to_dict(),
            "start_position": [float(v) for v in self.clip.start],
            **({"heading_frame": self.graph_metadata["heading_frame"]} if self.graph_metadata["heading_frame"] else {}),
            "root_frame": self.graph_metadata["root_frame"],
            "model": self.model_config.to_dict(),
            "train": self.config.to_dict(),
            "seed": self.seed,
            "device": str(self.device),
            "bf16": self.autocast,
            "compiled": None if self.forward is None else {"on": self.forward.compiled, "why": self.forward.why},
            "window": self.sampler.window,
            "crop": {"frames": self.sampler.crop, "why": self.sampler.crop_why},
            "foot_loss": {"on": self.extra_loss is not None, "why": self.foot_loss_why},
            "receptive_field": self.receptive_field,
            "parameters": count_parameters(self.model),
            "schedule": {"name": "cosine", "timesteps": NUM_TIMESTEPS},
            "step": self.step,
            "steps": self.config.steps,
            "finished": finished,
            "loss": None if math.isnan(self.loss) else self.loss,
            "elapsed_seconds": round(self.elapsed, 2),
            "watch": None if not self.config.check_every else {
                **self.watch.to_dict(), "stopped": self.stopped, "check_every": self.config.check_every},
            "sampling": self.sampling,
            CHECKSUMS: self.checksums,
            "updated": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        }

    # -------------------------------------------------------------- train
    def train_step(self) -> float:
        batch = self.sampler().to(self.device)
        t = torch.randint(0, NUM_TIMESTEPS, (batch.shape[0],), generator=self.generator).to(self.device)
        noise = torch.randn(batch.shape, generator=self.generator).to(self.device)
        if self.forward is None:
            self.forward = training_forward(self.model, (torch.zeros_like(batch), t), self.autocast,
                                            self.compile_mode, self.config.steps)
        self.model.train()
        with torch.autocast(device_type=self.device.type, dtype=torch.bfloat16, enabled=self.autocast):
            loss = self.diffusion.training_loss(self.forward.module, batch, t=t, noise=noise, extra=self.extra_loss)
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        self.optimizer.step()
        self.scheduler.step()
        self.step += 1
        if self.ema is not None:
            self._update_ema()
        return float(loss.detach())

    @torch.no_grad()
    def _update_ema(self) -> None:
        decay = min(self.config.ema, (1 + self.step) / (10 + self.step))
        for ema_param, param in zip(self.ema.parameters(), self.model.parameters()):
            ema_param.lerp_(param.detach(), 1.0 - decay)


def _compatible(previous: dict, run: Run) -> None:
    """Refuse to resume a run on another clip, codec or configuration."""
    if previous["clip"]["sha256"] != run.clip.info["sha256"]:
        raise SinMDMError(f"cannot resume: the run was trained on {previous['clip']['name']} (another file)")
    if previous["codec"] != json.loads(json.dumps(run.clip.codec.to_dict())):
        raise SinMDMError("cannot resume: the clip's feature encoding options differ from the run's")
    # steps and early_stop are the budget, which --steps may change; fields a run predates take their defaults;
    # whole_clip_frames matters only through the window it gives, compared below (runs before it are resumable)
    ignored = {"steps": None, "early_stop": None, "whole_clip_frames": None}
    before = dict(json.loads(json.dumps(TrainConfig.from_dict(previous["train"]).to_dict())), **ignored)
    now = dict(json.loads(json.dumps(run.config.to_dict())), **ignored)
    if before != now:
        changed = sorted(k for k in before if before.get(k) != now.get(k))
        raise SinMDMError(f"cannot resume: training configuration differs from the run's ({', '.join(changed)})")
    if previous["window"] != run.sampler.window:
        raise SinMDMError(f"cannot resume: the run trained on {previous['window']} frames at a time, this configuration "
                          f"on {run.sampler.window}")
    if previous["seed"] != run.seed:
        raise SinMDMError(f"cannot resume: the run used seed {previous['seed']}, not {run.seed}")


def _trim_log(run_dir: Path, step: int) -> None:
    """Drop log lines written after the checkpoint we resume from (and lines that are not records)."""
    if (run_dir / LOG).exists():
        kept = [line for line, record in log_records(run_dir) if record["step"] <= step]
        write_text_atomic(run_dir / LOG, "".join(line + "\n" for line in kept))


def _refuse_finished(run_dir: Path, previous: dict, run: Run) -> None:
    """A resumed run must have steps left: a finished run continues only when --steps raises its total."""
    if run.stopped and (not _falls_back(run) or "stage" in previous):
        raise SinMDMError(f"{run_dir} is finished: the quality watch stopped it at step {run.step} "
                          f"({stop_reason(run.stopped)}); train a new run to change its budget")
    if not run.stopped and run.step >= run.config.steps:
        where = "is finished" if previous["finished"] else f"is past --steps {run.config.steps}"
        raise SinMDMError(f"{run_dir} {where} at step {run.step}: pass --steps above {run.step} to train further")


def resumed_budget(run_dir: Path, config: TrainConfig) -> TrainConfig:
    """`config` with the run's own budget (steps, early stop), for a resume without --steps:
    the run continues to the total it was started with, not the preset's."""
    previous = TrainConfig.from_dict(load_config(Path(run_dir))["train"])
    return replace(config, steps=previous.steps, early_stop=previous.early_stop)


def train(
    clip_path: Path,
    run_dir: Path,
    config: TrainConfig,
    seed: int = 0,
    device: str = "auto",
    resume: bool = False,
    codec_options: dict | None = None,
    on_progress: Callable[[int, int, float, float], None] | None = None,
    on_check: Callable[[int, dict, int], None] | None = None,
    compile_mode: str = "auto",
    foot_loss_asked: bool = False,
) -> dict:
    """Train (or resume) a run; returns the final run config. `compile_mode`: auto, on or
    off (compiled.py). `foot_loss_asked`: the foot-contact loss was asked for by name, so a
    clip it cannot train is refused instead of trained without it."""
    run_dir = Path(run_dir)
    codec_options = codec_options or {}
    if compile_mode not in COMPILE_CHOICES:
        raise SinMDMError(f"compile must be one of {', '.join(COMPILE_CHOICES)}, got '{compile_mode}'")
    if config.steps < 1:
        raise SinMDMError("--steps must be at least 1")
    has_run = (run_dir / CONFIG).exists()
    if has_run and not resume:
        raise SinMDMError(f"{run_dir} already holds a run: pass --resume to continue it, or choose another --out")
    if resume and not has_run:
        raise SinMDMError(f"--resume: {run_dir} holds no run to continue (no {CONFIG})")
    clip = load_clip(Path(clip_path), config.fps, codec_options)
    run = Run(clip, config, seed, resolve_device(device), compile_mode)
    if foot_loss_asked and run.extra_loss is None and config.foot_loss > 0:
        raise SinMDMError(f"--foot-loss: {run.foot_loss_why.removeprefix('off: ')}")
    if has_run:
        previous = load_config(run_dir)
        _compatible(previous, run)
        run.load_state(load_state(run_dir))
        _refuse_finished(run_dir, previous, run)
        run.checksums, run.saved_step = previous.get(CHECKSUMS) or {}, run.step
        if not run.stopped:
            run.sampling = None  # measured again at the new end
        _trim_log(run_dir, run.step)
    check_writable_dir(run_dir)

    def checkpoint(best: dict | None = None) -> None:
        bad = run.nonfinite_weight()
        if bad is not None:
            raise run.diverged(f"non-finite weights ({bad})")
        run.checksums = save_run(run_dir, run.config_dict(finished=run.finished), run.state(), best)
        run.saved_step = run.step

    watch = _quality_watch(run) if config.check_every else None
    if not has_run:
        checkpoint()
    if on_progress:
        on_progress(run.step, config.steps, run.loss, 0.0)  # everything checked: training starts
    log = open(run_dir / LOG, "a", encoding="utf-8")
    losses: list[float] = []
    started, started_step = time.perf_counter(), run.step
    best = None  # a best check not saved yet
    try:
        while not run.finished:
            tick = time.perf_counter()
            loss = run.train_step()
            if not math.isfinite(loss):
                raise run.diverged(f"non-finite loss ({loss})")
            losses.append(loss)
            run.elapsed += time.perf_counter() - tick
            if run.step % config.log_every == 0 or run.step == config.steps:
                run.loss = float(np.mean(losses))
                losses.clear()
                rate = (run.step - started_step) / max(time.perf_counter() - started, 1e-9)
                lr = run.optimizer.param_groups[0]["lr"]
                log.write(json.dumps({"step": run.step, "loss": run.loss, "lr": lr, "it_s": rate,
                                      "elapsed": round(run.elapsed, 3)}) + "\n")
                log.flush()
                if on_progress:
                    on_progress(run.step, config.steps, run.loss, rate)
            checked = watch is not None and (run.step % config.check_every == 0 or run.step == config.steps)
            best = _check(run, watch, log, on_check) if checked else None
            if run.finished and watch is not None and run.sampling is None:
                run.sampling = sampling_defaults(watch, _kept_weights(run, run_dir, best), run.device)
                log.write(json.dumps({"step": run.step, "sampling": run.sampling}) + "\n")
                log.flush()
            if checked or run.step % config.checkpoint_every == 0 or run.finished:
                checkpoint(best)
    except KeyboardInterrupt:
        checkpoint(best)
        raise
    finally:
        log.close()
    if run.step == started_step:
        checkpoint()  # nothing to train (already at --steps): refresh the config's progress
    result = run.config_dict(finished=run.finished)
    stages = _train_fallbacks(run, clip_path, run_dir, seed, device, codec_options, on_progress, on_check, compile_mode)
    if not stages:
        return result
    first_best = (run.watch.best or {}).get("balance", -1.0)
    best_stage = max(stages, key=lambda s: (s["best"] or {}).get("balance", -1.0))
    chosen = (best_stage["best"] or {}).get("balance", -1.0) > first_best
    result["stages"] = [{**s, "chosen": chosen and s is best_stage} for s in stages]
    result["stage"] = {**best_stage, "chosen": chosen}
    write_text_atomic(run_dir / CONFIG, json.dumps(result, indent=2) + "\n")
    return result


def _room_for_a_stage(config: TrainConfig, used: int) -> bool:
    """Whether the steps left of the budget can hold a stage (two checks at least)."""
    return config.steps - used >= 2 * (config.check_every or 1)


def _train_fallbacks(run: Run, clip_path: Path, run_dir: Path, seed: int, device: str, codec_options: dict,
                     on_progress, on_check, compile_mode: str) -> list[dict]:
    """Train the run's fallback stages in turn (`_fallback_stages`), each on the budget the ones
    before left, while the last stopped for the same reason the first did; their records (the
    best check of each)."""
    config, records, offset, stopped = run.config, [], run.step, run.stopped
    for stage_config in _fallback_stages(run):
        if stop_reason(stopped) != stop_reason(run.stopped) or not _room_for_a_stage(config, offset):
            break
        stage_config = replace(stage_config, steps=config.steps - offset)
        stage_dir = run_dir / stage_dir_name(stage_config)
        start = offset

        def stage_progress(step: int, total: int, loss: float, rate: float, start: int = start) -> None:
            if on_progress:
                on_progress(start + step, config.steps, loss, rate)

        def stage_check(step: int, scores: dict, best_step: int, start: int = start) -> None:
            if on_check:
                on_check(start + step, scores, start + best_step)

        done = (stage_dir / CONFIG).exists() and load_config(stage_dir)["finished"]
        stage = load_config(stage_dir) if done else train(
            clip_path, stage_dir, stage_config, seed=seed, device=device, resume=(stage_dir / CONFIG).exists(),
            codec_options=codec_options, on_progress=stage_progress, on_check=stage_check, compile_mode=compile_mode)
        records.append({"dir": stage_dir.name, "norm": stage_config.norm, "foot_loss": stage_config.foot_loss,
                        "crop_edges": stage_config.crop_edges, "steps": stage["step"], "from_step": start,
                        "best": stage["watch"]["best"]})
        offset, stopped = start + stage["step"], stage["watch"].get("stopped")
    return records


def stage_dir_name(stage: TrainConfig) -> str:
    return (f"{STAGE_PREFIX}{stage.norm}" + ("-crop-edges" if stage.crop_edges > 0 else "")
            + ("-foot-loss" if stage.foot_loss > 0 else ""))


def tried_stages(config: dict) -> list[dict]:
    """The fallback stages a run tried (runs before "stages" recorded only the one they tried)."""
    return config.get("stages") or ([config["stage"]] if config.get("stage") else [])


def trained_seconds(run_dir: Path, config: dict) -> float:
    """Seconds of training of the run and every fallback stage it tried."""
    return config["elapsed_seconds"] + sum(load_config(Path(run_dir) / stage["dir"])["elapsed_seconds"]
                                           for stage in tried_stages(config))


def kept_stage(run_dir: Path, config: dict) -> dict | None:
    """The config of the run's fallback stage when the watch kept it over the first, else None."""
    stage = config.get("stage")
    return load_config(Path(run_dir) / stage["dir"]) if stage and stage.get("chosen") else None


def kept_sampling(run_dir: Path, config: dict) -> dict | None:
    """The sampling defaults measured on the weights export takes (the kept stage's)."""
    kept = kept_stage(run_dir, config)
    return (kept if kept is not None else config).get("sampling")


def _falls_back(run: Run) -> bool:
    """Whether the run, as it stopped, goes on to a fallback stage."""
    return bool(run.stopped) and _room_for_a_stage(run.config, run.step) and bool(_fallback_stages(run))


def _fallback_stages(run: Run) -> list[TrainConfig]:
    """What a run that stopped short of the band tries next, in order, each trained from scratch
    on the steps left (budgets are set by `_train_fallbacks`). A run that stopped COPYING: the other
    normalisation (`fallback_norm`, a strictly local model that copies less), then its own norm with
    the foot-contact loss matched to the clip's feet (`fallback_foot_loss`), which learns poses more
    slowly: whole-clip Xia normal copied under both norms and reached the band with it. A run that
    stopped STALLED: crop starts reaching the clip's ends (`stalled_crop_edges`: the idle's lost
    coverage sat at its ends) with the foot-contact loss at `stalled_foot_loss` (the idle: 95.2 %,
    18 of 20 samples plausible; BENCHMARKS.md). The foot loss only where the clip has contact joints
    and the run trained without it."""
    config = run.config
    plain = replace(config, fallback_norm=None, fallback_foot_loss=0.0, stalled_crop_edges=0.0, stalled_foot_loss=0.0)

    def with_feet(stage: TrainConfig, weight: float) -> TrainConfig:
        feet = replace(stage, foot_loss=weight, foot_loss_target="clip")
        takes = weight > 0 and config.foot_loss <= 0 and foot_loss_choice(run.clip.codec, feet)[0]
        return feet if takes else stage

    reason = stop_reason(run.stopped)
    stages = []
    if reason == COPYING:
        if config.fallback_norm and config.fallback_norm != config.norm:
            stages.append(replace(plain, norm=config.fallback_norm))
        feet = with_feet(plain, config.fallback_foot_loss)
        if feet is not plain:
            stages.append(feet)
    elif reason == STALLED:
        stage = with_feet(replace(plain, crop_edges=max(config.crop_edges, config.stalled_crop_edges)), config.stalled_foot_loss)
        if stage != plain:
            stages.append(stage)
    return stages


def _quality_watch(run: Run) -> QualityWatch:
    return QualityWatch(run.clip.bvh, run.clip.codec, run.diffusion.alphas_cumprod.numpy(), run.sampler.window,
                        run.receptive_field, run.clip.start, CheckSettings(cleanup=run.config.check_cleanup),
                        source_fps=run.clip.info["source_fps"], graph_metadata=run.graph_metadata)


def _check(run: Run, watch: QualityWatch, log, on_check) -> dict | None:
    """Score the EMA weights; return them (for best.pt, saved with the checkpoint that
    follows) when they balance best; stop when the watch says the run has peaked (unless
    the budget was forced)."""
    tick = time.perf_counter()
    weights = run.ema if run.ema is not None else run.model
    scores = watch.check(weights, run.device, to_beat=run.watch.best["balance"] if run.watch.best else None)
    best = None
    if run.watch.update(run.step, scores):
        best = {"step": run.step, "weights": copy.deepcopy(weights.state_dict()), "scores": scores}
    reason = run.watch.should_stop(run.config.patience, scores) if run.config.early_stop else None
    if reason == PEAKED:
        run.stopped = f"{PEAKED}: the balance peaked in the band at step {run.watch.best_step}"
    elif reason == STALLED:
        run.stopped = (f"{STALLED}: coverage fell to {scores['coverage']:.0f} % from {run.watch.best['coverage']:.0f} % "
                       f"at step {run.watch.best_step}, short of the band")
    elif reason == COPYING:
        run.stopped = (f"{COPYING}: coverage {scores['coverage']:.0f} % while global diversity fell to "
                       f"{scores['global_diversity']:.2f} (best balance at step {run.watch.best_step})")
    run.elapsed += time.perf_counter() - tick
    log.write(json.dumps({"step": run.step, "check": scores, "best_step": run.watch.best_step,
                          "stopped": run.stopped}) + "\n")
    log.flush()
    if on_check:
        on_check(run.step, scores, run.watch.best_step)
    return best


def _kept_weights(run: Run, run_dir: Path, best: dict | None) -> torch.nn.Module:
    """The weights export will use: the best check's (`best`, not saved yet, or best.pt)
    when the watch kept some."""
    model = copy.deepcopy(run.ema if run.ema is not None else run.model)
    if best is not None:
        model.load_state_dict(best["weights"])
    elif (run_dir / BEST).exists():
        model.load_state_dict(load_best(run_dir)["weights"])
    return model


CHECKPOINTS = ("best", "last")


def load_trained_model(run_dir: Path, use_ema: bool = True, checkpoint: str = "best") -> tuple[torch.nn.Module, dict]:
    """The run's denoiser in eval mode, with its config and which weights were taken
    (`config["chosen"]`): `best` = the watch's best-balanced check (best.pt) when the run
    kept one, else the last weights (EMA when the run kept them)."""
    if checkpoint not in CHECKPOINTS:
        raise SinMDMError(f"unknown checkpoint '{checkpoint}': use best or last")
    config = load_config(run_dir)
    stage = config.get("stage")
    if checkpoint == "best" and stage and stage.get("chosen"):
        model, inner = load_trained_model(Path(run_dir) / stage["dir"], use_ema, checkpoint)
        # what trained the kept weights is the stage's: its settings, its loss and where it ended on the run's steps
        return model, {**config, "model": inner["model"], "window": inner["window"], "train": inner["train"],
                       "step": stage["from_step"] + inner["step"], "loss": inner.get("loss"),
                       "receptive_field": inner["receptive_field"], "sampling": inner.get("sampling"),
                       "chosen": {**inner["chosen"], "stage": stage["dir"],
                                  "run_step": stage["from_step"] + inner["chosen"]["step"]}}
    model = Denoiser(ModelConfig.from_dict(config["model"]))
    if checkpoint == "best" and (Path(run_dir) / BEST).exists():
        best = load_best(run_dir)
        weights, chosen = best["weights"], {"checkpoint": "best", "step": int(best["step"]), "scores": best.get("scores")}
    else:
        state = load_state(run_dir)
        weights = state.get("ema") if use_ema and state.get("ema") is not None else state["model"]
        chosen = {"checkpoint": "last", "step": int(state["step"]), "scores": None}
    try:
        model.load_state_dict(weights)
    except RuntimeError as exc:
        raise SinMDMError(f"checkpoint of {run_dir} does not match its config ({str(exc)[:120]})") from None
    return model.eval(), {**config, "chosen": chosen}
