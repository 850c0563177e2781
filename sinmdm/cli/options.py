"""The options of `sample` and every edit command, declared once, and the one runner
they share: options checked, outputs planned (before any sampling), sampled, written."""

from __future__ import annotations

import inspect
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Callable, Optional

import typer

from ..runtime.model import MAX_THREADS
from ..runtime.options import DEFAULT_SMOOTH, DEFAULT_STEPS, EDGE_MARGIN, SamplingOptions
from ..runtime.smoothing import MAX_SMOOTH
from .common import console, print_json

if TYPE_CHECKING:
    from ..runtime.generate import GenerationResult
    from ..runtime.model import MotionModel

Models = Annotated[Optional[list[Path]], typer.Argument(
    help="Model .onnx file(s), one per window (default: the bundled demo model).")]
Ref = Annotated[Path, typer.Option("--ref", "-r", help="Reference BVH on the model's skeleton.")]
SourceFps = Annotated[Optional[float], typer.Option(
    "--source-fps", help="The clip's frame rate, overriding its Frame Time (for files where it is written wrong).")]
Count = Annotated[int, typer.Option("--count", "-n", help="How many motions (sample i uses seed + i).")]
Seed = Annotated[int, typer.Option("--seed", help="Seed of the first sample (0 .. 2^32-1).")]
Sampler = Annotated[str, typer.Option("--sampler", help="ddpm (ancestral) or ddim (deterministic with --eta 0).")]
Steps = Annotated[Optional[int], typer.Option("--steps", help="Denoising steps (default: the model's measured "
                                              f"setting from training, else {DEFAULT_STEPS}; 1000 = the paper's full chain).")]
Eta = Annotated[float, typer.Option("--eta", help="DDIM noise, 0..1 (0 = deterministic).")]
Hop = Annotated[Optional[int], typer.Option("--hop", help="Frames between overlapping windows (default: the model's "
                                            "measured setting, else half a window).")]
Margin = Annotated[int, typer.Option("--margin", help="Frames sampled beyond each end and cut off "
                                     "(steadier first and last frames; 0 = the paper's sampler).")]
Cleanup = Annotated[bool, typer.Option("--cleanup/--no-cleanup", help="Pin the feet (contact joints) where the model "
                                       "predicts contacts, with IK on the legs (removes foot sliding).")]
Smooth = Annotated[Optional[float], typer.Option("--smooth", help="Smooth the sampled motion over time: a Gaussian "
                                                 f"of this many frames (sigma, 0..{MAX_SMOOTH:g}; default: the model's measured "
                                                 f"setting, else {DEFAULT_SMOOTH:g}; 0 = off, the paper's sampler).")]
Threads = Annotated[Optional[int], typer.Option("--threads", help=f"onnxruntime threads, 1..{MAX_THREADS} "
                                                "(default: all cores).")]
Provider = Annotated[str, typer.Option("--provider", help="onnxruntime execution provider: cpu (default, the tested "
                                      "path), cuda, openvino, directml or coreml, where its onnxruntime build is installed.")]
Out = Annotated[Path, typer.Option("--out", "-o", help="Output directory.")]
Name = Annotated[str, typer.Option("--name", help="File name prefix (a plain name: files stay inside --out).")]
Format = Annotated[str, typer.Option("--format", help="bvh or glb (glb needs the preview extra).")]
Npz = Annotated[bool, typer.Option("--npz", help="Also write features and joint positions as .npz.")]
Preview = Annotated[bool, typer.Option("--preview", help="Also write a GIF preview (needs the preview extra).")]
Force = Annotated[bool, typer.Option("--force", help="Allow motions over an hour and overwrite existing files.")]
Json = Annotated[bool, typer.Option("--json", help="Print a JSON summary on stdout.")]


@dataclass(frozen=True)
class Context:
    """What a sampling command's body gets: the loaded model and the common options."""

    model: "MotionModel"
    options: SamplingOptions
    force: bool


@dataclass
class Job:
    """A sampling command's work, planned before any sampling: its output length, how to
    sample it, and what it adds to the summary (fields, and lines for the terminal)."""

    frames: int
    run: Callable[[Callable[[int, int], None]], "GenerationResult"]
    summary: dict = field(default_factory=dict)
    report: Callable[["GenerationResult"], tuple[dict, list[str]]] = lambda result: ({}, [])


def _common_parameters(default_name: str) -> list[inspect.Parameter]:
    keyword = inspect.Parameter.KEYWORD_ONLY
    common = [("count", Count, 1), ("seed", Seed, 0), ("sampler", Sampler, "ddpm"), ("steps", Steps, None),
              ("eta", Eta, 0.0), ("hop", Hop, None), ("margin", Margin, EDGE_MARGIN), ("cleanup", Cleanup, True),
              ("smooth", Smooth, None), ("threads", Threads, None), ("provider", Provider, "cpu"), ("out", Out, Path("sinmdm_out")), ("name", Name, default_name),
              ("fmt", Format, "bvh"), ("npz", Npz, False), ("preview", Preview, False), ("force", Force, False),
              ("as_json", Json, False)]
    return [inspect.Parameter(name, keyword, annotation=kind, default=default) for name, kind, default in common]


def sampling_command(app: typer.Typer):
    """Register `body(context, **own options) -> Job` as a command (named as the body, its
    docstring the help) taking the model files, its own options and every common sampling
    and output option (--name defaults to the command's name)."""

    def register(body: Callable[..., Job]) -> Callable[..., None]:
        own = list(inspect.signature(body, eval_str=True).parameters.values())[1:]
        models = inspect.Parameter("models", inspect.Parameter.POSITIONAL_OR_KEYWORD, annotation=Models, default=None)
        parameters = [models, *(p.replace(kind=inspect.Parameter.KEYWORD_ONLY) for p in own),
                      *_common_parameters(body.__name__)]

        def command(**values) -> None:
            own_values = {p.name: values.pop(p.name) for p in own}
            _run_sampling(body.__name__, body, own_values, **values)

        command.__name__, command.__doc__ = body.__name__, body.__doc__
        command.__signature__ = inspect.Signature(parameters)
        command.__annotations__ = {p.name: p.annotation for p in parameters}
        app.command(name=body.__name__)(command)
        return command

    return register


def load_cli_model(models: Optional[list[Path]], threads: Optional[int], provider: str = "cpu") -> "MotionModel":
    from ..runtime.model import load_model

    return load_model(models or None, threads=threads, provider=provider)


def _progress(label: str):
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    return Progress(TextColumn(f"[bold]{label}[/bold]"), BarColumn(), MofNCompleteColumn(),
                    TimeElapsedColumn(), TimeRemainingColumn(), console=console, transient=True,
                    disable=not console.is_terminal)


def _run_sampling(command: str, body: Callable[..., Job], own: dict, *, models, count, seed, sampler, steps, eta, hop,
                  margin, cleanup, smooth, threads, provider, out, name, fmt, npz, preview, force, as_json) -> None:
    from ..runtime.outputs import plan_sample_outputs
    from .writers import extra_writers

    options = SamplingOptions(count=count, seed=seed, sampler=sampler, steps=steps, eta=eta, hop=hop, margin=margin,
                              cleanup=cleanup, smooth=smooth)
    model = load_cli_model(models, threads, provider)
    job = body(Context(model, options, force), **own)
    resolved = options.resolve(model, job.frames)
    with plan_sample_outputs(out, name, options.seeds, fmt=fmt, npz=npz, preview=preview, force=force,
                             writers=extra_writers(fmt, preview),
                             values_per_sample=job.frames * model.codec.skeleton.num_channels) as outputs:
        with _progress(f"{command}: {count} x {job.frames} frames") as progress:
            task = progress.add_task(command, total=resolved.steps)
            result = job.run(lambda done, total: progress.update(task, completed=done, total=total))
        written = outputs.write(model, result)
    extra, notes = job.report(result)
    fps = model.codec.fps
    summary = {
        "command": command, "model": [str(d.path) for d in model.denoisers.values()], **job.summary,
        "frames": job.frames, "fps": fps, "seconds": job.frames / fps, "count": count, "seed": seed,
        "sampler": sampler, "steps": result.options.steps, "eta": eta, "hop": result.options.hop, "margin": margin,
        "cleanup": cleanup, "smooth": result.options.smooth, "elapsed_seconds": round(result.seconds, 3), "files": [str(p) for p in written], **extra,
    }
    if as_json:
        print_json(summary)
        return
    console.print(f"{command}: wrote {len(written)} file(s) to [bold]{out}[/bold]: {count} x {job.frames} frames "
                  f"({job.frames / fps:.1f} s at {fps:g} fps) in {result.seconds:.2f} s")
    for note in notes:
        console.print(note)
