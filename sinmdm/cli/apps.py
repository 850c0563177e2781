"""`sinmdm-run inbetween|expand|keyframes|control|harmonize`: thin commands over
sinmdm.runtime.applications, taking every option of `sample` (cli/options.py)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from ..runtime import applications as apps
from ..runtime.sampler import check_guide
from .options import Context, Job, Ref, SourceFps, sampling_command

Ramp = Annotated[int, typer.Option("--ramp", help="Frames of linear blend at each border.")]
KeepStart = Annotated[float, typer.Option("--keep-start", help="Share of the reference kept at the start, in [0, 1).")]
KeepEnd = Annotated[float, typer.Option("--keep-end", help="Share kept at the end, in [0, 1).")]
Before = Annotated[float, typer.Option("--before", help="Share of the reference's length to add before.")]
After = Annotated[float, typer.Option("--after", help="Share to add after.")]
Joints = Annotated[Optional[str], typer.Option("--joints", help="upper-body, lower-body, or comma-separated joint names.")]


def _plan_job(context: Context, ref: Path, plan: "apps.Plan") -> Job:
    check_guide(context.model, plan.guide)  # before the output folder exists
    return Job(plan.frames, lambda progress: apps.run_plan(context.model, plan, context.options, progress, context.force),
               summary={"reference": str(ref)})


def _reference(context: Context, ref: Path, source_fps: Optional[float]) -> "apps.Reference":
    return apps.load_reference(context.model, ref, source_fps, context.force)


def register(app: typer.Typer) -> None:
    @sampling_command(app)
    def inbetween(context: Context, ref: Ref, source_fps: SourceFps = None, keep_start: KeepStart = apps.INBETWEEN_KEEP,
                  keep_end: KeepEnd = apps.INBETWEEN_KEEP, ramp: Ramp = apps.INBETWEEN_RAMP) -> Job:
        """Keep the start and end of a clip and generate the motion in between."""
        reference = _reference(context, ref, source_fps)
        return _plan_job(context, ref, apps.plan_inbetween(context.model, reference, keep_start, keep_end, ramp))

    @sampling_command(app)
    def expand(context: Context, ref: Ref, source_fps: SourceFps = None, before: Before = apps.EXPAND_SHARE,
               after: After = apps.EXPAND_SHARE, ramp: Ramp = apps.EXPAND_RAMP) -> Job:
        """Extend a clip with new motion before and after it."""
        reference = _reference(context, ref, source_fps)
        return _plan_job(context, ref, apps.plan_expand(context.model, reference, before, after, ramp, context.force))

    @sampling_command(app)
    def keyframes(context: Context, ref: Ref, source_fps: SourceFps = None,
                  frames: Annotated[Optional[str], typer.Option("--frames", help="Comma-separated reference frames to keep (model frame rate).")] = None,
                  every: Annotated[Optional[int], typer.Option("--every", help="Keep every N-th frame instead (default: one a second).")] = None,
                  hold: Annotated[int, typer.Option("--hold", help="Also keep this many frames either side of each key.")] = 0) -> Job:
        """Keep sparse key poses of a clip and generate the motion around them."""
        reference = _reference(context, ref, source_fps)
        keys = apps.parse_keyframes(frames) if frames else apps.default_keyframes(context.model, reference, every)
        return _plan_job(context, ref, apps.plan_keyframes(context.model, reference, keys, hold))

    @sampling_command(app)
    def control(context: Context, ref: Ref, source_fps: SourceFps = None, joints: Joints = None,
                subtree: Annotated[Optional[str], typer.Option("--subtree", help="Keep this joint and everything below it.")] = None,
                trajectory: Annotated[bool, typer.Option("--trajectory", help="Keep the root path (x/z motion and heading); the reference may be any skeleton.")] = False) -> Job:
        """Keep some joints (or the root path) of a clip and generate the rest of the body."""
        reference = apps.load_control_reference(context.model, ref, source_fps, joints, subtree, trajectory, context.force)
        return _plan_job(context, ref, apps.plan_control(context.model, reference, joints, subtree, trajectory))

    @sampling_command(app)
    def harmonize(context: Context, ref: Ref, source_fps: SourceFps = None,
                  frames: Annotated[Optional[str], typer.Option("--frames", help="START:STOP: harmonize only these frames of the reference, pasted into a generated motion.")] = None,
                  joints: Joints = None,
                  factor: Annotated[int, typer.Option("--factor", help="Low-pass down/up-sampling factor N of ILVR (at least 1).")] = 2,
                  border: Annotated[int, typer.Option("--border", help="Frames around a pasted portion that are harmonized too.")] = apps.HARMONIZE_BORDER) -> Job:
        """Restyle a clip with the model's motion (style transfer), or blend a pasted portion in."""
        reference = _reference(context, ref, source_fps)
        span = apps.parse_frame_range(frames) if frames else None
        apps.check_harmonize(context.model, reference, factor, span, joints, border)

        def run(progress):
            return apps.harmonize(context.model, reference, context.options, factor, span, joints, border, progress,
                                  context.force)

        return Job(reference.frames, run, summary={"reference": str(ref)})
