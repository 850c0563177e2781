"""`sinmdm-run`: everything the torch-free runtime does."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import numpy as np
import typer
from rich.table import Table
from rich.tree import Tree

from ..runtime.errors import OptionError
from ..runtime.options import EDGE_MARGIN
from .common import RootOption, UpOption, console, print_json, run_app
from .options import Context, Eta, Hop, Job, Json, Margin, Sampler, Seed, Smooth, SourceFps, Steps, Threads, sampling_command

app = typer.Typer(
    name="sinmdm-run",
    help="Sample, edit and convert motion with a trained SinMDM model (no torch needed).",
    no_args_is_help=True,
    add_completion=False,
)

UnitsOption = typer.Option("auto", "--units", help="File units: auto, m, cm, mm, in, ft, or metres per unit.")
ContactsOption = typer.Option(None, "--contacts", help="Comma-separated contact joint names (default: detected).")


def _contacts(value: Optional[str]) -> str | list[str]:
    return "auto" if not value else [name.strip() for name in value.split(",") if name.strip()]


def _joint_tree(skeleton, contact_names: set[str]) -> Tree:
    tree = Tree("[bold]skeleton[/bold]")
    nodes: dict[int, Tree] = {}
    for j, name in enumerate(skeleton.names):
        parent = int(skeleton.parents[j])
        channels = " ".join(c[0] + c[1:4] for c in skeleton.channels[j]) or "no channels"
        mark = " [green](contact)[/green]" if name in contact_names else ""
        label = f"{name} [dim]{channels}[/dim]{mark}"
        nodes[j] = (tree if parent < 0 else nodes[parent]).add(label)
    return tree


@app.command()
def inspect(
    clip: Path = typer.Argument(..., help="A BVH file."),
    units: str = UnitsOption,
    source_fps: SourceFps = None,
    contacts: Optional[str] = ContactsOption,
    fps: float = typer.Option(30.0, "--fps", help="Feature frame rate used to detect contacts."),
    root: Optional[str] = RootOption,
    up: str = UpOption,
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
) -> None:
    """Show a clip's skeleton, length, units, trajectory joint, up axis, contacts and feature width."""
    from ..runtime.animation import nominal_fps
    from ..runtime.bvh import read_bvh
    from ..runtime.features import build_codec, skeleton_size
    from ..runtime.masks import has_body_halves, units_warning_for
    from ..runtime.rig import AXIS_NAMES, analyse_rig

    bvh = read_bvh(clip)
    codec = build_codec(bvh, fps=fps, units=units, contacts=_contacts(contacts), source_fps=source_fps, root=root, up=up)
    rig = analyse_rig(codec.animation(bvh, source_fps), codec.scale, root, up)
    skeleton = bvh.skeleton
    clip_fps = source_fps or nominal_fps(bvh.frame_time)
    contact_names = [skeleton.names[j] for j in codec.contact_joints]
    warnings = []
    if not 5 <= clip_fps <= 1000:
        warnings.append(f"frame time {bvh.frame_time:g} s ({clip_fps:g} fps) looks wrong; pass --source-fps")
    humanoid = has_body_halves(codec)
    if units == "auto" and (warning := units_warning_for(codec)):
        warnings.append(warning)
    info = {
        "file": str(clip),
        "joints": skeleton.num_joints,
        "roots": [skeleton.names[r] for r in skeleton.roots],
        "end_sites": len(skeleton.end_sites),
        "channels": skeleton.num_channels,
        "frames": bvh.frames,
        "frame_time": bvh.frame_time,
        "fps": clip_fps,
        "seconds": bvh.frames / clip_fps,
        "metres_per_unit": codec.scale,
        "size_m": skeleton_size(skeleton) * codec.scale,
        "rotation_orders": sorted({skeleton.rotation_order(j) for j in range(skeleton.num_joints)} - {""}),
        "trajectory_joint": None if codec.trajectory_joint is None else skeleton.names[codec.trajectory_joint],
        "fixed_joints": [skeleton.names[j] for j in codec.fixed_joints],
        "up_axis": AXIS_NAMES[codec.up_axis],
        "humanoid_halves": humanoid,
        "contact_joints": contact_names,
        "feature_fps": codec.fps,
        "feature_width": codec.width,
        "why": list(rig.reasons),
        "warnings": warnings,
    }
    if as_json:
        print_json(info)
        return
    console.print(_joint_tree(skeleton, set(contact_names)))
    table = Table(show_header=False, box=None)
    for key, value in info.items():
        if key not in ("warnings", "why"):
            table.add_row(key.replace("_", " "), ", ".join(map(str, value)) if isinstance(value, list) else f"{value:.6g}" if isinstance(value, float) else str(value))
    console.print(table)
    for reason in rig.reasons:
        console.print(f"[dim]{reason}[/dim]")
    for warning in warnings:
        console.print(f"[yellow]warning:[/yellow] {warning}")


@app.command()
def convert(
    source: Path = typer.Argument(..., help="Input BVH."),
    target: Path = typer.Argument(..., help="Output BVH."),
    fps: Optional[float] = typer.Option(None, "--fps", help="Output frame rate (default: the input's)."),
    units: str = UnitsOption,
    source_fps: SourceFps = None,
    contacts: Optional[str] = ContactsOption,
    root: Optional[str] = RootOption,
    up: str = UpOption,
    force: bool = typer.Option(False, "--force", help="Overwrite an existing output file."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
) -> None:
    """Read a clip, encode it to model features, decode and write it back."""
    from ..runtime.animation import animation_from_bvh, global_positions, nominal_fps
    from ..runtime.atomic import OutputSet
    from ..runtime.bvh import format_bvh, read_bvh
    from ..runtime.features import build_codec, skeleton_size

    if target.suffix.lower() not in (".bvh", ".glb"):
        raise OptionError("target", f"cannot write '{target.suffix}' files: use .bvh or .glb")
    with OutputSet.for_file(target, force=force, option="target") as output:
        bvh = read_bvh(source)
        rate = fps or source_fps or nominal_fps(bvh.frame_time)
        codec = build_codec(bvh, fps=rate, units=units, contacts=_contacts(contacts), source_fps=source_fps, root=root, up=up)
        features = codec.encode(bvh, source_fps=source_fps)
        out = codec.decode_bvh(features, codec.start_position(bvh, source_fps=source_fps))
        if target.suffix.lower() == ".glb":
            from ..preview.gltf import bvh_to_glb

            output.write_bytes(target.name, bvh_to_glb(out, units=units, root=root, up=up))
        else:
            output.write_text(target.name, format_bvh(out))
        output.commit()
    summary = {"source": str(source), "target": str(target), "frames": out.frames, "fps": out.fps,
               "feature_width": codec.width}
    if fps is None:
        expected = global_positions(animation_from_bvh(bvh))
        got = global_positions(animation_from_bvh(out))
        error = float(np.abs(expected - got).max()) / skeleton_size(bvh.skeleton)
        summary["max_position_error_of_size"] = error
    if as_json:
        print_json(summary)
    else:
        console.print(f"wrote [bold]{target}[/bold]: {out.frames} frames at {out.fps:g} fps, {codec.width} features")
        if "max_position_error_of_size" in summary:
            console.print(f"round-trip joint position error: {summary['max_position_error_of_size']:.2e} of skeleton size")


@sampling_command(app)
def sample(
    context: Context,
    seconds: Annotated[Optional[float], typer.Option("--seconds", help="Length in seconds.")] = None,
    frames: Annotated[Optional[int], typer.Option("--frames", help="Length in frames (default: 10 s).")] = None,
    loop: Annotated[bool, typer.Option("--loop", help="A seamless cycle: the file holds T frames whose last flows into "
                                       "the first; the root moves by the loop displacement (summary) each cycle. At "
                                       "least one window long.")] = False,
) -> Job:
    """Generate new motions from a trained model and write them as BVH."""
    from ..runtime.generate import generate
    from ..runtime.options import length_in_frames

    model = context.model
    length = length_in_frames(model.codec.fps, seconds, frames, context.force)

    def report(result) -> tuple[dict, list[str]]:
        if not loop:
            return {}, []
        from ..runtime.rig import AXIS_NAMES

        axes = [AXIS_NAMES[a] for a in model.codec.horizontal_axes]
        # per clip: root metres per cycle along the root's horizontal axes (its parent's frame)
        moves = [dict(zip(axes, map(float, d))) for d in result.loop_displacement]
        text = "; ".join(", ".join(f"{a} {v:+.3f}" for a, v in d.items()) for d in moves)
        return {"loop": True, "loop_displacement_m": moves}, [f"loops of {length} frames; the root moves per cycle (m): {text}"]

    return Job(length, lambda progress: generate(model, length, context.options, loop=loop, progress=progress),
               report=report)


@app.command()
def vectors(
    model: Path = typer.Argument(..., help="The model's .onnx file (one window)."),
    out: Path = typer.Option(..., "--out", "-o", help="Output directory (new or empty; --force writes into it)."),
    frames: int = typer.Option(160, "--frames", help="Length of the sample in frames."),
    seed: Seed = 0,
    steps: Steps = None,
    sampler: Sampler = "ddpm",
    eta: Eta = 0.0,
    hop: Hop = None,
    margin: Margin = EDGE_MARGIN,
    smooth: Smooth = None,
    loop: bool = typer.Option(False, "--loop", help="Sample a seamless cycle (circular windows)."),
    threads: Threads = None,
    force: bool = typer.Option(False, "--force", help="Write into a non-empty directory, overwriting vectors there."),
    as_json: Json = False,
) -> None:
    """Write golden test vectors of one sample (every step's x_t, x0_hat and noise, the features,
    the decoded joint positions) as float32 files and a manifest, for ports (docs/runtime.md)."""
    from ..runtime.model import load_model
    from ..runtime.options import SamplingOptions, check_length
    from ..runtime.vectors import write_vectors

    options = SamplingOptions(seed=seed, sampler=sampler, steps=steps, eta=eta, hop=hop, margin=margin, smooth=smooth)
    loaded = load_model([model], threads=threads)
    check_length(frames, loaded.codec.fps)
    document = write_vectors(loaded, model, out, frames, options, loop=loop, force=force)
    if as_json:
        print_json(document)
        return
    opts = document["options"]
    console.print(f"vectors: wrote {len(document['arrays']) + 2} files to [bold]{out}[/bold]: {frames} frames, "
                  f"seed {seed}, {opts['sampler']} {opts['steps']} steps, hop {opts['hop']}, smoothing {opts['smooth']:g}, "
                  f"{len(document['window_starts'])} window(s) of {document['window']}")


def _register_optional_commands() -> None:
    from .apps import register as register_apps
    from .preview_commands import register as register_preview

    register_apps(app)
    register_preview(app)


_register_optional_commands()
main = run_app(app)

if __name__ == "__main__":
    main()
