"""`sinmdm-run inbetween|expand|keyframes|control|harmonize`: thin commands over
sinmdm.runtime.applications, sharing the sampling options of `sample`."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from ..runtime.errors import SinMDMError
from ..runtime.sampler import DEFAULT_STEPS
from .common import console, print_json

Models = typer.Argument(None, help="Model .onnx file(s) (default: the bundled demo model).")
Ref = typer.Option(..., "--ref", "-r", help="Reference BVH on the model's skeleton.")
RefFps = typer.Option(None, "--ref-fps", help="Override the reference's frame rate (files with a wrong Frame Time).")
Count = typer.Option(1, "--count", "-n", help="How many motions (sample i uses seed + i).")
Seed = typer.Option(0, "--seed")
Sampler = typer.Option("ddpm", "--sampler", help="ddpm or ddim.")
Steps = typer.Option(None, "--steps", help="Denoising steps (default: the model's measured setting, else "
                     f"{DEFAULT_STEPS}; 1000 = the paper's full chain).")
Out = typer.Option(Path("sinmdm_out"), "--out", "-o", help="Output directory.")
Force = typer.Option(False, "--force", help="Overwrite existing files.")
Json = typer.Option(False, "--json", help="Print a JSON summary.")
Preview = typer.Option(False, "--preview", help="Also write a GIF preview (needs the preview extra).")
Cleanup = typer.Option(True, "--cleanup/--no-cleanup", help="Pin the feet where the model predicts contacts (leg IK).")


def _run(command: str, models, ref: Path, ref_fps, count, seed, sampler, steps, out, force, as_json, preview,
         make_plan, cleanup: bool = True) -> None:
    from ..runtime.applications import load_reference, run_plan
    from ..runtime.generate import GenerationRequest
    from ..runtime.outputs import write_outputs
    from ..runtime.model import load_model

    model = load_model(models or None)
    steps = model.default_steps if steps is None else steps
    plan = make_plan(model, lambda: load_reference(model, ref, ref_fps))
    request = GenerationRequest(frames=plan.frames, count=count, seed=seed, sampler=sampler, steps=steps, cleanup=cleanup)
    result = run_plan(model, plan, request)
    written = write_outputs(model, result, out, name=command, preview=preview, force=force)
    summary = {"command": command, "reference": str(ref), "frames": plan.frames, "count": count, "seed": seed,
               "steps": steps, "cleanup": cleanup, "elapsed_seconds": round(result.seconds, 3), "files": [str(p) for p in written]}
    if as_json:
        print_json(summary)
    else:
        console.print(f"{command}: wrote {len(written)} file(s) to [bold]{out}[/bold] ({plan.frames} frames each, "
                      f"{result.seconds:.2f} s)")


def _range(text: Optional[str]) -> Optional[tuple[int, int]]:
    if not text:
        return None
    try:
        start, stop = (int(v) for v in text.split(":"))
    except ValueError:
        raise SinMDMError(f"--frames takes START:STOP (frames), got '{text}'") from None
    return start, stop


def register(app: typer.Typer) -> None:
    @app.command()
    def inbetween(models: Optional[list[Path]] = Models, ref: Path = Ref, ref_fps: Optional[float] = RefFps,
                  keep_start: float = typer.Option(0.25, "--keep-start", help="Share of the reference kept at the start."),
                  keep_end: float = typer.Option(0.25, "--keep-end", help="Share kept at the end."),
                  ramp: int = typer.Option(10, "--ramp", help="Frames of linear blend at each border."),
                  count: int = Count, seed: int = Seed, sampler: str = Sampler, steps: int = Steps,
                  out: Path = Out, force: bool = Force, as_json: bool = Json, preview: bool = Preview,
                  cleanup: bool = Cleanup) -> None:
        """Keep the start and end of a clip and generate the motion in between."""
        from ..runtime.applications import plan_inbetween

        _run("inbetween", models, ref, ref_fps, count, seed, sampler, steps, out, force, as_json, preview,
             lambda m, load: plan_inbetween(m, load(), keep_start, keep_end, ramp), cleanup)

    @app.command()
    def expand(models: Optional[list[Path]] = Models, ref: Path = Ref, ref_fps: Optional[float] = RefFps,
               before: float = typer.Option(0.15, "--before", help="Share of the reference's length to add before."),
               after: float = typer.Option(0.15, "--after", help="Share to add after."),
               ramp: int = typer.Option(6, "--ramp", help="Frames of linear blend at each border."),
               count: int = Count, seed: int = Seed, sampler: str = Sampler, steps: int = Steps,
               out: Path = Out, force: bool = Force, as_json: bool = Json, preview: bool = Preview,
               cleanup: bool = Cleanup) -> None:
        """Extend a clip with new motion before and after it."""
        from ..runtime.applications import plan_expand

        _run("expand", models, ref, ref_fps, count, seed, sampler, steps, out, force, as_json, preview,
             lambda m, load: plan_expand(m, load(), before, after, ramp), cleanup)

    @app.command()
    def keyframes(models: Optional[list[Path]] = Models, ref: Path = Ref, ref_fps: Optional[float] = RefFps,
                  frames: Optional[str] = typer.Option(None, "--frames", help="Comma-separated reference frames to keep (model frame rate)."),
                  every: Optional[int] = typer.Option(None, "--every", help="Keep every N-th frame instead."),
                  hold: int = typer.Option(0, "--hold", help="Also keep this many frames either side of each key."),
                  count: int = Count, seed: int = Seed, sampler: str = Sampler, steps: int = Steps,
                  out: Path = Out, force: bool = Force, as_json: bool = Json, preview: bool = Preview,
                  cleanup: bool = Cleanup) -> None:
        """Keep sparse key poses of a clip and generate the motion around them."""
        from ..runtime.applications import plan_keyframes

        def plan(m, load):
            reference = load()
            if frames:
                try:
                    keys = [int(v) for v in frames.split(",") if v.strip()]
                except ValueError:
                    raise SinMDMError(f"--frames takes comma-separated frame numbers, got '{frames}'") from None
            else:
                step = every or int(round(m.codec.fps))
                keys = list(range(0, reference.frames, step))
            return plan_keyframes(m, reference, keys, hold)

        _run("keyframes", models, ref, ref_fps, count, seed, sampler, steps, out, force, as_json, preview, plan,
             cleanup)

    @app.command()
    def control(models: Optional[list[Path]] = Models, ref: Path = Ref, ref_fps: Optional[float] = RefFps,
                joints: Optional[str] = typer.Option(None, "--joints", help="upper-body, lower-body, or comma-separated joint names to keep."),
                subtree: Optional[str] = typer.Option(None, "--subtree", help="Keep this joint and everything below it."),
                trajectory: bool = typer.Option(False, "--trajectory", help="Keep the root path (x/z motion and heading); the reference may be any skeleton."),
                count: int = Count, seed: int = Seed, sampler: str = Sampler, steps: int = Steps,
                out: Path = Out, force: bool = Force, as_json: bool = Json, preview: bool = Preview,
                cleanup: bool = Cleanup) -> None:
        """Keep some joints (or the root path) of a clip and generate the rest of the body."""
        from ..runtime.applications import load_reference, load_trajectory, plan_control

        def plan(m, load):
            reference = load_trajectory(m, ref, ref_fps) if trajectory and not (joints or subtree) else load_reference(m, ref, ref_fps)
            return plan_control(m, reference, joints, subtree, trajectory)

        _run("control", models, ref, ref_fps, count, seed, sampler, steps, out, force, as_json, preview, plan,
             cleanup)

    @app.command()
    def harmonize(models: Optional[list[Path]] = Models, ref: Path = Ref, ref_fps: Optional[float] = RefFps,
                  frames: Optional[str] = typer.Option(None, "--frames", help="START:STOP: harmonize only these frames of the reference, pasted into a generated motion."),
                  joints: Optional[str] = typer.Option(None, "--joints", help="Harmonize only these joints (upper-body, lower-body or names)."),
                  factor: int = typer.Option(2, "--factor", help="Low-pass down/up-sampling factor N of ILVR."),
                  border: int = typer.Option(10, "--border", help="Frames around a pasted portion that are harmonized too."),
                  count: int = Count, seed: int = Seed, sampler: str = Sampler, steps: int = Steps,
                  out: Path = Out, force: bool = Force, as_json: bool = Json, preview: bool = Preview,
                  cleanup: bool = Cleanup) -> None:
        """Restyle a clip with the model's motion (style transfer), or blend a pasted portion in."""
        from ..runtime.applications import plan_harmonize
        from ..runtime.generate import GenerationRequest, generate

        def plan(m, load):
            reference = load()
            span = _range(frames)
            base = None
            if span or joints:
                request = GenerationRequest(frames=reference.frames, count=1, seed=seed, sampler=sampler,
                                            steps=m.default_steps if steps is None else steps)
                base = generate(m, request).features[0]
            return plan_harmonize(m, reference, factor, span, joints, base, border)

        _run("harmonize", models, ref, ref_fps, count, seed, sampler, steps, out, force, as_json, preview, plan,
             cleanup)
