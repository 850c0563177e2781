"""`sinmdm-run preview`: stick-figure GIF/MP4 renders and the HTML viewer.

The preview libraries are imported only when the command runs, so the rest of
the CLI works without the preview extra."""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

from ..runtime.atomic import OutputSet
from ..runtime.errors import SinMDMError
from .common import RootOption, UpOption, console, print_json

OUTPUT_SUFFIXES = (".gif", ".mp4", ".html")


def register(app: typer.Typer) -> None:
    app.command()(preview)


def preview(
    clips: List[Path] = typer.Argument(..., help="BVH files, shown side by side (e.g. the input, then outputs)."),
    out: Path = typer.Option(..., "--out", "-o", help="Output file: .gif, .mp4 or .html (interactive viewer)."),
    html: bool = typer.Option(False, "--html", help="Also write the interactive viewer beside --out, with the suffix .html."),
    source_fps: Optional[float] = typer.Option(
        None, "--source-fps", help="Override the clips' frame rate (for files with a wrong Frame Time)."),
    units: str = typer.Option("auto", "--units", help="File units: auto, m, cm, mm, in, ft, or metres per unit."),
    labels: Optional[str] = typer.Option(None, "--labels", help="Comma-separated labels, one per clip (default: file names)."),
    size: Optional[str] = typer.Option(None, "--size", help="Image size WIDTHxHEIGHT in pixels (default 360x360 per clip)."),
    max_seconds: Optional[float] = typer.Option(None, "--max-seconds", help="Render at most this many seconds."),
    root: Optional[str] = RootOption,
    up: str = UpOption,
    force: bool = typer.Option(False, "--force", help="Overwrite existing output files."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
) -> None:
    """Render clips as stick figures to a GIF or MP4, or an interactive HTML viewer."""
    suffix = out.suffix.lower()
    if suffix not in OUTPUT_SUFFIXES:
        raise SinMDMError(f"cannot write '{out.suffix or out.name}' previews: use .gif, .mp4 or .html")
    html_out = out.with_suffix(".html")
    outputs = [out] + ([html_out] if html and suffix != ".html" else [])
    label_list = _labels(labels, len(clips))
    image_size = _size(size)
    from ..runtime.rig import parse_up

    parse_up(up)  # refuse a bad --up before reading any clip
    files = OutputSet(out.parent, [path.name for path in outputs], force=force)  # every output check before any work

    from ..runtime.bvh import read_bvh

    bvhs = [read_bvh(path) for path in clips]
    summary: dict = {"clips": [str(c) for c in clips], "outputs": [str(p) for p in outputs]}
    with files:
        if suffix != ".html":
            from ..preview.render import render_file

            infos = []
            files.write(out.name, lambda tmp: infos.append(render_file(
                bvhs, tmp, fps=source_fps, labels=label_list, size=image_size, max_seconds=max_seconds,
                units=units, root=root, up=up, suffix=suffix)))
            summary.update(frames=infos[0].frames, fps=infos[0].fps, size=list(infos[0].size))
        if html or suffix == ".html":
            from ..preview.viewer import viewer_html

            files.write_text(html_out.name, viewer_html(bvhs, labels=label_list, fps=source_fps, units=units,
                                                        root=root, up=up))
        files.commit()
    if as_json:
        print_json(summary)
        return
    if "frames" in summary:
        width, height = summary["size"]
        console.print(f"wrote [bold]{out}[/bold]: {summary['frames']} frames at {summary['fps']:g} fps, {width}x{height}")
    if html or suffix == ".html":
        console.print(f"wrote [bold]{html_out}[/bold]: open it in a browser (drag to orbit, space to play)")


def _labels(value: Optional[str], count: int) -> Optional[list[str]]:
    if value is None:
        return None
    labels = [label.strip() for label in value.split(",")]
    if len(labels) != count:
        raise SinMDMError(f"--labels has {len(labels)} labels for {count} clips")
    return labels


def _size(value: Optional[str]) -> Optional[tuple[int, int]]:
    if value is None:
        return None
    try:
        width, height = (int(part) for part in value.lower().split("x"))
    except ValueError:
        raise SinMDMError(f"--size must look like 640x360, got '{value}'") from None
    if not (32 <= width <= 8192 and 32 <= height <= 8192):
        raise SinMDMError(f"--size must be between 32x32 and 8192x8192, got '{value}'")
    return width, height
