"""`sinmdm`: train, export and evaluate. torch is imported only inside the
commands that need it (train, info, export)."""

from __future__ import annotations

import math

from pathlib import Path
from typing import Optional

import typer
from rich.table import Table

from ..runtime.errors import SinMDMError
from .common import RootOption, UpOption, console, print_json, run_app

app = typer.Typer(
    name="sinmdm",
    help="Train SinMDM on one motion clip, export it to ONNX, evaluate samples.",
    no_args_is_help=True,
    add_completion=False,
)


def _require_torch() -> None:
    try:
        import torch  # noqa: F401
    except ImportError:
        raise SinMDMError("this command needs the training extra: pip install 'sinmdm[train]'") from None


@app.command()
def train(
    clip: Path = typer.Argument(..., help="The BVH clip to learn from."),
    out: Path = typer.Option(..., "--out", "-o", help="Run directory (checkpoints, config, log)."),
    preset: str = typer.Option("cpu", "--preset", help="Recipe: cpu (the watched recipe: 3.5-19 min on 2 cores as measured) or paper (the authors', needs a GPU)."),
    steps: Optional[int] = typer.Option(None, "--steps", help="Total iterations to reach (default: the preset's; with --resume, the run's own). "
                                         "A finished run continues only when --steps raises its total."),
    device: str = typer.Option("auto", "--device", help="auto (CUDA, then MPS, then CPU), cpu, cuda, mps."),
    seed: int = typer.Option(0, "--seed"),
    resume: bool = typer.Option(False, "--resume", help="Continue the run in --out from its last (verified) checkpoint."),
    width: Optional[int] = typer.Option(None, "--width", help="Network width (paper: 256)."),
    crop: Optional[int] = typer.Option(None, "--crop", help="Training crop length in frames (cpu preset: 64, and a clip of at most 96 frames trains whole; an explicit --crop applies to every clip)."),
    crop_edges: Optional[float] = typer.Option(None, "--crop-edges", help="How far, as a share of the crop, crop starts may fall off the clip's ends before being clamped in (default 0: uniform starts, which rarely train the clip's first and last second; 0.25 trains them about as often as the middle; measured in BENCHMARKS.md: it helped the idle and cost the crab)."),
    batch: Optional[int] = typer.Option(None, "--batch", help="Batch size (default 64)."),
    checkpoint_every: Optional[int] = typer.Option(None, "--checkpoint-every", help="Iterations between checkpoints."),
    fps: float = typer.Option(30.0, "--fps", help="Feature frame rate."),
    units: str = typer.Option("auto", "--units", help="File units: auto, m, cm, mm, in, ft, or metres per unit."),
    source_fps: Optional[float] = typer.Option(None, "--source-fps", help="Override the clip's frame rate."),
    contacts: Optional[str] = typer.Option(None, "--contacts", help="Comma-separated contact joints (default: detected)."),
    root: Optional[str] = RootOption,
    up: str = UpOption,
    check_every: Optional[int] = typer.Option(None, "--check-every", help="Iterations between quality checks of the "
                                              "EMA weights (cpu preset: 200; 0 = never): the best-balanced is kept and exported."),
    patience: Optional[int] = typer.Option(None, "--patience", help="Checks without improvement, once in the quality "
                                           "band, before training stops early (default 3; --steps trains to the end)."),
    norm: Optional[str] = typer.Option(None, "--norm", help="group (the paper's GroupNorm over the window) or frame (per-frame, a strictly local model; see BENCHMARKS.md)."),
    velocity_unit: Optional[str] = typer.Option(None, "--velocity-unit", help="frame (the paper: root velocity in metres per frame) or second (metres per second: the root channels at the rotations' size; see BENCHMARKS.md)."),
    root_frame: Optional[str] = typer.Option(None, "--root-frame", help="world (the paper: the trajectory joint's rotation and velocity in the world), heading (seen from the character's heading, plus its rate of turn: a clip that turns keeps turning; a trajectory from another skeleton cannot guide it) or auto (the cpu preset: heading for a clip that turns more than 10 deg/s on average; see BENCHMARKS.md)."),
    check_cleanup: Optional[bool] = typer.Option(None, "--check-cleanup/--no-check-cleanup", help="Quality checks sample as `sample` does: the foot cleanup on, shaking samples smoothed as calibration would (the `cpu` preset's default; see BENCHMARKS.md)."),
    compile: Optional[bool] = typer.Option(None, "--compile/--no-compile", help="Train through torch.compile (default: when the run has 600 steps or more on a CPU or CUDA device; about 1.4x faster after some 45 s of compiling; falls back to eager if compiling fails)."),
    ema: Optional[float] = typer.Option(None, "--ema", help="Decay of the weights' moving average that is checked and exported (cpu preset: 0.999, reached after some 9,000 steps of warm-up; 0 = no average, the raw weights).", show_default=False),
    loss_weighting: Optional[str] = typer.Option(None, "--loss-weighting", help="Loss weight over the noise level: uniform (the paper) or min-snr (min(SNR, 5), mean 1; see BENCHMARKS.md)."),
    foot_loss: Optional[float] = typer.Option(None, "--foot-loss", help="Weight of a foot-contact loss on the prediction's contact joints, by forward kinematics (0 = the paper's loss alone; what it holds them to: --foot-loss-target; measured weights per clip in BENCHMARKS.md)."),
    foot_loss_target: Optional[str] = typer.Option(None, "--foot-loss-target", help="What the foot-contact loss holds the contact joints to: 'still' (the clip's planted joints kept still, MDM's) or 'clip' (their velocity on every frame matched to the clip's, weighted by the noise level's share of signal)."),
) -> None:
    """Train a denoiser on one clip."""
    _require_torch()
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    from dataclasses import replace

    from ..train.checkpoint import CONFIG
    from ..runtime.features import VELOCITY_UNITS
    from ..train.diffusion import LOSS_WEIGHTINGS
    from ..train.foot_loss import FOOT_LOSS_TARGETS
    from ..train.model import NORM_KINDS
    from ..train.presets import preset as get_preset
    from ..train.trainer import ROOT_FRAME_CHOICES, kept_sampling, resumed_budget, train as run_training, trained_seconds, tried_stages

    if norm is not None and norm not in NORM_KINDS:
        raise SinMDMError(f"--norm must be {' or '.join(NORM_KINDS)}, got '{norm}'")
    if velocity_unit is not None and velocity_unit not in VELOCITY_UNITS:
        raise SinMDMError(f"--velocity-unit must be {' or '.join(VELOCITY_UNITS)}, got '{velocity_unit}'")
    if root_frame is not None and root_frame not in ROOT_FRAME_CHOICES:
        raise SinMDMError(f"--root-frame must be {', '.join(ROOT_FRAME_CHOICES)}, got '{root_frame}'")
    if foot_loss is not None and not (foot_loss >= 0 and math.isfinite(foot_loss)):
        raise SinMDMError(f"--foot-loss must be 0 or a positive number, got {foot_loss}")
    if foot_loss_target is not None and foot_loss_target not in FOOT_LOSS_TARGETS:
        raise SinMDMError(f"unknown --foot-loss-target {foot_loss_target!r}: use {' or '.join(FOOT_LOSS_TARGETS)}")
    if ema is not None and not 0 <= ema < 1:
        raise SinMDMError(f"--ema must be 0 (no average) or a decay below 1, got {ema}")
    if loss_weighting is not None and loss_weighting not in LOSS_WEIGHTINGS:
        raise SinMDMError(f"--loss-weighting must be {' or '.join(LOSS_WEIGHTINGS)}, got '{loss_weighting}'")
    if crop_edges is not None and not 0 <= crop_edges <= 1:
        raise SinMDMError(f"--crop-edges must be a share of the crop from 0 to 1, got {crop_edges}")
    if check_every is not None and check_every < 0:
        raise SinMDMError(f"--check-every must be 0 (never) or more, got {check_every}")
    config = get_preset(preset).with_overrides(
        steps=steps, width=width, crop=crop, crop_edges=crop_edges, batch=batch, checkpoint_every=checkpoint_every, fps=fps, norm=norm,
        velocity_unit=velocity_unit, root_frame=root_frame, foot_loss=foot_loss, foot_loss_target=foot_loss_target, check_cleanup=check_cleanup,
        early_stop=False if steps else None, patience=patience,  # --steps forces a fixed budget: the watch still keeps the best
        loss_weighting=loss_weighting,
    )
    if crop is not None:
        config = replace(config, whole_clip_frames=None)
    if ema is not None:
        config = replace(config, ema=ema or None)
    if check_every is not None:
        config = config.with_overrides(check_every=check_every or None) if check_every else replace(config, check_every=None)
    if resume and steps is None and (out / CONFIG).is_file():
        config = resumed_budget(out, config)
    codec_options = {"units": units, "source_fps": source_fps, "root": root, "up": up,
                     "contacts": "auto" if not contacts else [c.strip() for c in contacts.split(",")]}
    if units == "auto" and not resume:
        _warn_about_units(clip, config.fps, codec_options)
    # shown from the first step on, so that an error found before training is the only output
    progress = Progress(
        TextColumn("[bold]training[/bold]"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
        TextColumn("loss {task.fields[loss]:.4f}"), TextColumn("{task.fields[rate]:.2f} it/s"),
        TimeElapsedColumn(), TimeRemainingColumn(), console=console, transient=False,
    )
    task = progress.add_task("train", total=config.steps, loss=float("nan"), rate=0.0)

    def on_progress(step: int, total: int, loss: float, rate: float) -> None:
        progress.start()
        progress.update(task, completed=step, loss=loss, rate=rate)

    def on_check(step: int, scores: dict, best_step: int) -> None:
        progress.console.print(f"check at step {step}: {_scores_line(scores)}"
                               + ("  [bold]best[/bold]" if best_step == step else f"  (best: step {best_step})"))

    try:
        result = run_training(clip, out, config, seed=seed, device=device, resume=resume,
                              codec_options=codec_options, on_progress=on_progress, on_check=on_check,
                              compile_mode="auto" if compile is None else ("on" if compile else "off"),
                              foot_loss_asked=bool(foot_loss))
        stages = tried_stages(result)
        done = result["step"] + sum(stage["steps"] for stage in stages)
        progress.update(task, completed=done)
    finally:
        if progress.live.is_started:
            progress.stop()
    seconds = trained_seconds(out, result)
    console.print(
        f"run [bold]{out}[/bold]: step {done}/{result['steps']}" + (f" ({result['step']} in its first stage)" if stages else "")
        + f", loss {result['loss']}, {result['parameters']:,} parameters, window {result['window']} frames, "
        f"{seconds:.0f} s of training"
    )
    watch = result.get("watch")
    if watch and watch.get("best"):
        console.print(f"kept step {watch['best_step']} (best balance): {_scores_line(watch['best'])}"
                      + (f"; stopped early: {watch['stopped']}" if watch.get("stopped") else ""))
    for stage in stages:
        console.print(f"fallback stage ({stage['dir']}, {_stage_words(stage)}, {stage['steps']} steps from step "
                      f"{stage['from_step']}): " + (_scores_line(stage["best"]) if stage.get("best") else "no check kept")
                      + ("  [bold]chosen[/bold]" if stage["chosen"] else "  (not kept)"))
    sampling = kept_sampling(out, result)
    if sampling:
        console.print(f"sampling defaults measured on the kept weights: {sampling['steps']} steps, hop {sampling['hop']}"
                      + _smooth_words(sampling))


def _smooth_words(sampling: dict) -> str:
    """", smoothing 1 frame" where the measured defaults carry a smoothing (older runs have none)."""
    smooth = sampling.get("smooth")
    return "" if smooth is None else (f", smoothing {smooth:g} frame(s)" if smooth else ", no smoothing")


def _scores_line(scores: dict) -> str:
    return (f"coverage {scores['coverage']:.1f} %, global {scores['global_diversity']:.2f}, "
            f"local {scores['local_diversity']:.2f}, balance {scores['balance']:.3f}, "
            f"jitter {scores['jitter_ratio']:.1f}x ({scores['check_seconds']:.1f} s)")


def _warn_about_units(clip: Path, fps: float, codec_options: dict) -> None:
    from ..runtime.bvh import read_bvh
    from ..runtime.features import build_codec
    from ..runtime.masks import units_warning_for

    warning = units_warning_for(build_codec(read_bvh(clip), fps=fps, **codec_options))
    if warning:
        console.print(f"[yellow]warning:[/yellow] {warning}")


@app.command()
def info(
    run_dir: Path = typer.Argument(..., help="A training run directory."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
) -> None:
    """Show a run's configuration, parameter count and progress."""
    from ..train.checkpoint import load_config
    from ..train.trainer import kept_sampling, tried_stages

    config = load_config(run_dir)
    summary = {
        "parameters": config["parameters"],
        "step": config["step"],
        "steps": config["steps"],
        "finished": config["finished"],
        "preset": config["train"]["preset"],
        "clip": config["clip"],
        "window": config["window"],
        "receptive_field": config["receptive_field"],
        "feature_width": config["model"]["features"] - bool(config.get("heading_frame")),  # the graph adds the turn rate
        "loss": config["loss"],
        "elapsed_seconds": config["elapsed_seconds"],
        "device": config["device"],
        "compiled": config.get("compiled"),
        "root_frame": config.get("root_frame"),
        "crop": config.get("crop"),
        "foot_loss": config.get("foot_loss"),
        "train": config["train"],
        "model": config["model"],
        "watch": config.get("watch"),
        "sampling": kept_sampling(run_dir, config),  # what export writes into the model
        "stage": config.get("stage"),
        "stages": tried_stages(config),
    }
    if as_json:
        print_json(summary)
        return
    table = Table(show_header=False, box=None)
    for key in ("preset", "step", "steps", "finished", "parameters", "window", "receptive_field",
                "feature_width", "loss", "elapsed_seconds", "device"):
        value = summary[key]
        table.add_row(key.replace("_", " "), f"{value:,}" if isinstance(value, int) and not isinstance(value, bool) else str(value))
    table.add_row("clip", f"{config['clip']['name']} ({config['clip']['frames']} frames, sha256 {config['clip']['sha256'][:12]})")
    chosen = config.get("root_frame") or {"frame": config["train"].get("root_frame", "world"), "why": "asked for"}
    table.add_row("root frame", f"{chosen['frame']} ({chosen['why']})")
    if config.get("crop"):
        table.add_row("training crop", config["crop"]["why"])
    if config.get("foot_loss"):
        table.add_row("foot-contact loss", config["foot_loss"]["why"])
    if summary["compiled"]:
        table.add_row("compiled", f"{'yes' if summary['compiled']['on'] else 'no'}: {summary['compiled']['why']}")
    console.print(table)
    watch = config.get("watch") or {}
    stage = config.get("stage")
    if watch.get("best"):
        first = "first stage's best" if stage and stage["chosen"] else "kept"
        console.print(f"{first}: step {watch['best_step']} of {watch['checks']} checks, {_scores_line(watch['best'])}")
        if watch.get("stopped"):
            console.print(f"stopped early: {watch['stopped']}")
        _print_checks(run_dir)
    for stage in tried_stages(config):
        inner = load_config(Path(run_dir) / stage["dir"])
        best = (inner.get("watch") or {}).get("best")
        console.print(f"fallback stage {stage['dir']} ({_stage_words(stage)}, steps {stage['from_step']}-"
                      f"{stage['from_step'] + inner['step']}): " + ("[bold]kept[/bold]" if stage["chosen"] else "not kept")
                      + (f", its best at run step {stage['from_step'] + inner['watch']['best_step']}: {_scores_line(best)}"
                         if best else "") + f" (details: sinmdm info {Path(run_dir) / stage['dir']})")
    sampling = summary["sampling"]
    if sampling:
        console.print(f"sampling defaults: {sampling['steps']} steps, hop {sampling['hop']}{_smooth_words(sampling)} "
                      f"(coverage {sampling['scores']['coverage']:.1f} %, global {sampling['scores']['global_diversity']:.2f})")


def _stage_words(stage: dict) -> str:
    return (f"--norm {stage['norm']}" + (f", --crop-edges {stage['crop_edges']:g}" if stage.get("crop_edges") else "")
            + (f", --foot-loss {stage['foot_loss']:g}" if stage.get("foot_loss") else ""))


def _print_checks(run_dir: Path) -> None:
    from ..train.checkpoint import check_records

    checks = check_records(run_dir)
    table = Table(title="quality checks (EMA weights)")
    for column in ("step", "coverage %", "global", "local", "balance", "jitter", "turning off", "pace off", "planted", "lift", "s"):
        table.add_column(column, justify="right")
    for record in checks:
        c = record["check"]
        # turning and pace: the distance from the clip's over what the balance allows (the term is allowed / off)
        off = {key: (f"{c[key]:.1f} / {c[allowed]:.1f}" if key == "turning_distance_deg_s" else f"{c[key]:.2f} / {c[allowed]:.2f}")
               if key in c and allowed in c else "-"
               for key, allowed in (("turning_distance_deg_s", "turning_allowed_deg_s"), ("pace_distance_m_s", "pace_allowed_m_s"))}
        table.add_row(str(record["step"]), f"{c['coverage']:.1f}", f"{c['global_diversity']:.2f}",
                      f"{c['local_diversity']:.2f}", f"{c['balance']:.3f}",
                      f"{c['jitter_ratio']:.1f}" + (" s" if c.get("smooth") else ""), off["turning_distance_deg_s"],
                      off["pace_distance_m_s"],
                      f"{c['planted_share']:.0%} / {c['planted_needed']:.0%}" if "planted_needed" in c else "-",
                      f"{c['foot_lift_ratio']:.2f}x" if "foot_lift_ratio" in c else "-",
                      f"{c['check_seconds']:.1f}")
    console.print(table)


@app.command()
def export(
    run_dir: Path = typer.Argument(..., help="A finished training run directory."),
    out: Path = typer.Option(..., "--out", "-o", help="Output name: NAME.onnx becomes NAME_w<window>.onnx."),
    window: Optional[list[int]] = typer.Option(None, "--window", "-w", help="Window length(s) in frames (default: the training length)."),
    opset: int = typer.Option(18, "--opset", help="ONNX opset: 18 (default) or 17."),
    force: bool = typer.Option(False, "--force", help="Overwrite existing files."),
    checkpoint: str = typer.Option("best", "--checkpoint", help="best (the quality watch's best-balanced check, "
                                   "when the run kept one) or last (the final weights)."),
    as_json: bool = typer.Option(False, "--json", help="Print a JSON summary."),
) -> None:
    """Export the denoiser to ONNX, one verified graph per window length."""
    _require_torch()
    from ..export.onnx_export import export_run
    from ..runtime.model_format import sidecar_path

    results = export_run(run_dir, out, windows=window or None, opset=opset, force=force, checkpoint=checkpoint,
                         on_warning=lambda text: console.print(f"[yellow]warning:[/yellow] {text}"))
    if as_json:
        print_json([{"path": str(r.path), "sidecar": str(sidecar_path(r.path)), "window": r.window,
                     "max_abs_diff": r.max_abs_diff, "opset": r.opset, "ir_version": r.ir_version, "bytes": r.bytes,
                     "ops": r.ops} for r in results])
        return
    for r in results:
        console.print(f"wrote [bold]{r.path}[/bold] (metadata also in {sidecar_path(r.path).name}): window {r.window}, "
                      f"opset {r.opset}, IR {r.ir_version}, {r.bytes / 1e6:.1f} MB, parity with torch {r.max_abs_diff:.1e}")


@app.command()
def calibrate(
    models: list[Path] = typer.Argument(..., help="The model's .onnx windows."),
    clip: Path = typer.Option(..., "--clip", help="The clip the model learned (checked against its sha256)."),
    samples: int = typer.Option(6, "--samples", help="Motions per candidate setting (the training watch uses 6)."),
    cleanup: Optional[bool] = typer.Option(None, "--cleanup/--no-cleanup", help="Sample with the foot cleanup (default: as the run's quality checks did, --check-cleanup)."),
    source_fps: Optional[float] = typer.Option(None, "--source-fps", help="Override the clip's frame rate."),
    threads: Optional[int] = typer.Option(None, "--threads", help="onnxruntime threads (default: all cores)."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
) -> None:
    """Measure a model's sampling defaults (steps, hop, smoothing) against its clip and store them in its metadata."""
    _require_torch()
    from ..eval.balance import BALANCE_TOLERANCE
    from ..export.calibrate import calibrate_model

    chosen = calibrate_model(models, clip, samples=samples, source_fps=source_fps, threads=threads, cleanup=cleanup)
    if as_json:
        print_json(chosen)
        return
    table = Table("steps", "hop", "smooth", "coverage %", "global div", "local div", "jitter (x clip)", "balance", "seconds")
    for t in chosen["trials"]:
        table.add_row(str(t["steps"]), str(t["hop"]), f"{t['smooth']:g}", f"{t['coverage']:.1f}", f"{t['global_diversity']:.2f}",
                      f"{t['local_diversity']:.2f}", f"{t['jitter_ratio']:.2f}", f"{t['balance']:.3f}",
                      f"{t['check_seconds']:.1f}")
    console.print(table)
    console.print(f"sampling defaults: {chosen['steps']} steps, hop {chosen['hop']}{_smooth_words(chosen)} (the cheapest "
                  f"setting within {BALANCE_TOLERANCE:g} of the first's balance; smoothing also where it calms jittery "
                  f"samples for little diversity; sampled "
                  f"{'with' if chosen['cleanup'] else 'without'} the foot cleanup), written into {', '.join(str(m) for m in models)}")


@app.command()
def quantize(
    models: list[Path] = typer.Argument(..., help="The model's .onnx windows (float32, as exported)."),
    clip: Path = typer.Option(..., "--clip", help="The clip the model learned: the quality check scores against it."),
    samples: int = typer.Option(12, "--samples", help="Motions sampled with each graph for the quality check."),
    source_fps: Optional[float] = typer.Option(None, "--source-fps", help="Override the clip's frame rate."),
    threads: Optional[int] = typer.Option(None, "--threads", help="onnxruntime threads (default: all cores)."),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="Folder for the _int8 files (default: beside the model)."),
    force: bool = typer.Option(False, "--force", help="Replace existing _int8 files."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
) -> None:
    """Write a faster mixed-precision copy of each window (MODEL_w64_int8.onnx: int8 convolutions
    for the noisy steps, float32 for the last ones), only if it keeps the model's quality."""
    _require_torch()
    from ..export.quantize import quantize_model

    checked = quantize_model(models, clip, samples=samples, source_fps=source_fps, threads=threads, force=force,
                             out=out)
    if as_json:
        print_json(checked)
        return
    table = Table("graph", "coverage %", "global div", "local div", "jitter (x clip)", "balance", "check seconds")
    for name in ("float32", "mixed"):
        s = checked[name]
        table.add_row(name, f"{s['coverage']:.1f}", f"{s['global_diversity']:.2f}", f"{s['local_diversity']:.2f}",
                      f"{s['jitter_ratio']:.2f}", f"{s['balance']:.3f}", f"{s['check_seconds']:.1f}")
    console.print(table)
    console.print(f"{checked['samples']} samples each at {checked['steps']} steps, hop {checked['hop']}; int8 above "
                  f"t = {checked['int8_above_t']}; written: {', '.join(checked['outputs'])}")


def _register_optional_commands() -> None:
    from .evaluate import register as register_eval

    register_eval(app)


_register_optional_commands()
main = run_app(app)

if __name__ == "__main__":
    main()
