"""`sinmdm-run`: everything the torch-free runtime does."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np
import typer
from rich.table import Table
from rich.tree import Tree

from ..runtime.errors import SinMDMError
from ..runtime.sampler import DEFAULT_STEPS as DEFAULT_STEPS_CLI, EDGE_MARGIN
from .common import RootOption, UpOption, console, print_json, run_app

app = typer.Typer(
    name="sinmdm-run",
    help="Sample, edit and convert motion with a trained SinMDM model (no torch needed).",
    no_args_is_help=True,
    add_completion=False,
)

UnitsOption = typer.Option("auto", "--units", help="File units: auto, m, cm, mm, in, ft, or metres per unit.")
SourceFpsOption = typer.Option(None, "--source-fps", help="Override the clip's frame rate (for files with a wrong Frame Time).")
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
    source_fps: Optional[float] = SourceFpsOption,
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
    source_fps: Optional[float] = SourceFpsOption,
    contacts: Optional[str] = ContactsOption,
    root: Optional[str] = RootOption,
    up: str = UpOption,
    force: bool = typer.Option(False, "--force", help="Overwrite an existing output file."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
) -> None:
    """Read a clip, encode it to model features, decode and write it back."""
    from ..runtime.animation import animation_from_bvh, global_positions, nominal_fps
    from ..runtime.bvh import read_bvh, write_bvh
    from ..runtime.features import build_codec, skeleton_size

    if target.exists() and not force:
        raise SinMDMError(f"{target} exists; pass --force to overwrite")
    if target.suffix.lower() not in (".bvh", ".glb"):
        raise SinMDMError(f"cannot write '{target.suffix}' files: use .bvh or .glb")
    bvh = read_bvh(source)
    rate = fps or source_fps or nominal_fps(bvh.frame_time)
    codec = build_codec(bvh, fps=rate, units=units, contacts=_contacts(contacts), source_fps=source_fps, root=root, up=up)
    features = codec.encode(bvh, source_fps=source_fps)
    out = codec.decode_bvh(features, codec.start_position(bvh, source_fps=source_fps))
    if target.suffix.lower() == ".glb":
        from ..preview.gltf import write_glb

        write_glb(out, target, units=units, root=root, up=up)
    else:
        write_bvh(target, out)
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


ModelArgument = typer.Argument(None, help="Model .onnx file(s), one per window (default: the bundled demo model).")


def _progress(total_label: str):
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    return Progress(TextColumn(f"[bold]{total_label}[/bold]"), BarColumn(), MofNCompleteColumn(),
                    TimeElapsedColumn(), TimeRemainingColumn(), console=console, transient=True)


@app.command()
def sample(
    models: Optional[list[Path]] = ModelArgument,
    seconds: Optional[float] = typer.Option(None, "--seconds", help="Length in seconds."),
    frames: Optional[int] = typer.Option(None, "--frames", help="Length in frames (default: twice the window, or 10 s)."),
    count: int = typer.Option(1, "--count", "-n", help="How many motions (sample i uses seed + i)."),
    seed: int = typer.Option(0, "--seed"),
    sampler: str = typer.Option("ddpm", "--sampler", help="ddpm (ancestral) or ddim (deterministic with --eta 0)."),
    steps: Optional[int] = typer.Option(None, "--steps", help="Denoising steps (default: the model's measured setting "
                                        f"from training, else {DEFAULT_STEPS_CLI}; 1000 = the paper's full chain)."),
    eta: float = typer.Option(0.0, "--eta", help="DDIM noise (0 = deterministic)."),
    hop: Optional[int] = typer.Option(None, "--hop", help="Frames between overlapping windows (default: the model's "
                                      "measured setting, else half a window)."),
    loop: bool = typer.Option(False, "--loop", help="A seamless cycle: the file holds T frames whose last flows into the "
                              "first; the root moves by the loop displacement (summary) each cycle. At least one window long."),
    margin: int = typer.Option(EDGE_MARGIN, "--margin", help="Frames sampled beyond each end and cut off "
                               "(steadier first and last frames; 0 = the paper's sampler)."),
    cleanup: bool = typer.Option(True, "--cleanup/--no-cleanup", help="Pin the feet (contact joints) where the model "
                                 "predicts contacts, with IK on the legs (removes foot sliding)."),
    out: Path = typer.Option(Path("sinmdm_out"), "--out", "-o", help="Output directory."),
    name: str = typer.Option("sample", "--name", help="File name prefix."),
    fmt: str = typer.Option("bvh", "--format", help="bvh or glb (glb needs the preview extra)."),
    npz: bool = typer.Option(False, "--npz", help="Also write features and joint positions as .npz."),
    preview: bool = typer.Option(False, "--preview", help="Also write a GIF preview (needs the preview extra)."),
    threads: Optional[int] = typer.Option(None, "--threads", help="onnxruntime threads (default: all cores)."),
    force: bool = typer.Option(False, "--force", help="Allow very long motions and overwrite existing files."),
    as_json: bool = typer.Option(False, "--json", help="Print a JSON summary on stdout."),
) -> None:
    """Generate new motions from a trained model and write them as BVH."""
    from ..runtime.generate import GenerationRequest, generate
    from ..runtime.outputs import write_outputs
    from ..runtime.model import load_model

    model = load_model(models or None, threads=threads)
    length = _length(model, seconds, frames, force)
    steps = model.default_steps if steps is None else steps
    hop = model.default_hop(length) if hop is None else hop
    request = GenerationRequest(frames=length, count=count, seed=seed, sampler=sampler, steps=steps, eta=eta, hop=hop,
                                loop=loop, cleanup=cleanup, margin=margin)
    with _progress(f"sampling {count} x {length} frames") as progress:
        task = progress.add_task("sample", total=steps if steps else len(model.alphas_cumprod))
        result = generate(model, request, progress=lambda done, total: progress.update(task, completed=done, total=total))
    written = write_outputs(model, result, out, name=name, fmt=fmt, npz=npz, preview=preview, force=force)
    summary = {
        "model": [str(d.path) for d in model.denoisers.values()],
        "frames": length, "fps": model.codec.fps, "seconds": length / model.codec.fps,
        "count": count, "seed": seed, "sampler": sampler, "steps": steps, "hop": hop, "cleanup": cleanup,
        "elapsed_seconds": round(result.seconds, 3), "files": [str(p) for p in written],
    }
    if loop:
        from ..runtime.rig import AXIS_NAMES

        axes = [AXIS_NAMES[a] for a in model.codec.horizontal_axes]
        # per clip: root metres per cycle along the root's horizontal axes (its parent's frame)
        summary["loop"] = True
        summary["loop_displacement_m"] = [dict(zip(axes, map(float, d))) for d in result.loop_displacement]
    if as_json:
        print_json(summary)
    else:
        console.print(f"wrote {len(written)} file(s) to [bold]{out}[/bold]: {count} x {length} frames "
                      f"({length / model.codec.fps:.1f} s at {model.codec.fps:g} fps) in {result.seconds:.2f} s")
        if loop:
            moves = "; ".join(", ".join(f"{a} {v:+.3f}" for a, v in d.items()) for d in summary["loop_displacement_m"])
            console.print(f"loops of {length} frames; the root moves per cycle (m): {moves}")


MAX_SECONDS = 3600.0


def _length(model, seconds: Optional[float], frames: Optional[int], force: bool) -> int:
    if seconds is not None and frames is not None:
        raise SinMDMError("give --seconds or --frames, not both")
    if seconds is not None:
        if not seconds > 0:
            raise SinMDMError("--seconds must be positive")
        length = int(round(seconds * model.codec.fps))
    elif frames is not None:
        length = frames
    else:
        length = int(round(10 * model.codec.fps))
    if length < 1:
        raise SinMDMError("the length must be at least 1 frame")
    if length > MAX_SECONDS * model.codec.fps and not force:
        raise SinMDMError(f"{length} frames is over {MAX_SECONDS / 60:.0f} minutes; pass --force if you mean it")
    return length


def _register_optional_commands() -> None:
    from .apps import register as register_apps
    from .preview_commands import register as register_preview

    register_apps(app)
    register_preview(app)


_register_optional_commands()
main = run_app(app)

if __name__ == "__main__":
    main()
