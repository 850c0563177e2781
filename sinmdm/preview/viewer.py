"""A self-contained HTML viewer: one file with the motion as JSON and a small
canvas-2D renderer (viewer.html), no network and no libraries."""

from __future__ import annotations

import html
import json
import math
from importlib import resources
from pathlib import Path
from typing import Sequence

import numpy as np

from ..runtime.atomic import write_text_atomic
from ..runtime.bvh import BVH
from ..runtime.errors import SinMDMError
from . import CLIP_COLOURS, StickFigure, nice_step, smooth_track, stick_figure

SIGNIFICANT_STEPS = 2000  # positions are stored as integers of about size / 2000 (1 mm for a person)


def write_viewer(
    clips: Sequence[BVH],
    out_html: str | Path,
    labels: Sequence[str] | None = None,
    fps: float | None = None,
    units: str | float = "auto",
    title: str | None = None,
    root: str | None = None,
    up: str | None = None,
) -> Path:
    """Write one HTML file that plays the clips side by side in 3-D."""
    out_html = Path(out_html)
    write_text_atomic(out_html, viewer_html(clips, labels=labels, fps=fps, units=units, title=title, root=root, up=up))
    return out_html


def viewer_html(
    clips: Sequence[BVH],
    labels: Sequence[str] | None = None,
    fps: float | None = None,
    units: str | float = "auto",
    title: str | None = None,
    root: str | None = None,
    up: str | None = None,
) -> str:
    if not clips:
        raise SinMDMError("no clips to show")
    if labels is not None and len(labels) != len(clips):
        raise SinMDMError(f"got {len(labels)} labels for {len(clips)} clips")
    figures = [stick_figure(clip, None if labels is None else labels[i], fps, units, root, up)
               for i, clip in enumerate(clips)]
    payload = viewer_data(figures)
    template = resources.files(__package__).joinpath("viewer.html").read_text(encoding="utf-8")
    # "</" inside the JSON would end the <script> element early.
    data = json.dumps(payload, separators=(",", ":")).replace("</", "<\\/")
    page_title = title or "sinmdm: " + ", ".join(f.label for f in figures)
    return template.replace("__TITLE__", html.escape(page_title)).replace("__DATA__", data)


def viewer_data(figures: list[StickFigure]) -> dict:
    """Positions in metres as integers of `quantum`, clips spread along X, and
    the smoothed mean root path the camera follows."""
    heights = [float(np.ptp(f.points[..., 1], axis=1).max()) for f in figures]
    widths = [float(max(np.ptp(f.points[..., 0], axis=1).max(), np.ptp(f.points[..., 2], axis=1).max())) for f in figures]
    height = max(max(heights), 1e-6)
    spacing = max(max(widths), height) * 1.3
    quantum = 10.0 ** math.floor(math.log10(height / SIGNIFICANT_STEPS))
    floor = min(float(f.points[..., 1].min()) for f in figures)

    shifted = []
    for i, figure in enumerate(figures):
        start = figure.points[0, figure.root]
        offset = np.array([(i - (len(figures) - 1) / 2) * spacing - start[0], 0.0, -start[2]])
        shifted.append(StickFigure(figure.label, figure.fps, figure.points + offset, figure.parents, figure.root,
                                   figure.names))

    rate = max(f.fps for f in shifted)
    duration = max(f.seconds for f in shifted)
    times = np.arange(max(1, round(duration * rate))) / rate
    roots = np.mean([f.at(times)[:, f.root][:, [0, 2]] for f in shifted], axis=0)
    track = smooth_track(roots, rate)

    view_radius = max(height, (len(figures) - 1) * spacing / 2 + height * 0.6)
    grid_step = nice_step(height / 4)

    def integers(values: np.ndarray) -> list[int]:
        return np.round(values / quantum).astype(np.int64).reshape(-1).tolist()

    return {
        "quantum": quantum,
        "duration": duration,
        "floor": round(floor, 6),
        "height": round(height, 6),
        "view_radius": round(view_radius, 6),
        "grid_step": grid_step,
        "grid_lines": min(60, math.ceil(view_radius * 3 / grid_step)),  # on each side of the followed point
        "track": {"fps": rate, "xz": integers(track)},
        "clips": [
            {
                "label": f.label,
                "colour": CLIP_COLOURS[i % len(CLIP_COLOURS)],
                "fps": f.fps,
                "frames": f.frames,
                "parents": f.parents.tolist(),
                "points": integers(f.points),
            }
            for i, f in enumerate(shifted)
        ],
    }

