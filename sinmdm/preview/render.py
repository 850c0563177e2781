"""Stick-figure previews as GIF or MP4, drawn with matplotlib's Agg backend.

Speed comes from drawing the figure once and then, per frame, only restoring
the static background and redrawing three line collections per panel (grid,
shadow, bones) whose 2-D coordinates come from our own orthographic 3/4
projection; mplot3d would re-sort and re-project every artist each frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Iterator, Sequence

import numpy as np

from ..runtime.atomic import OutputSet
from ..runtime.bvh import BVH
from ..runtime.errors import SinMDMError
from . import CLIP_COLOURS, StickFigure, import_extra, nice_step, smooth_track, stick_figure

FORMATS = {".gif": 50.0, ".mp4": 60.0}  # highest playback rate per format: browsers slow GIF delays < 20 ms
PANEL_SIZE = (360, 360)
BACKGROUND = "#f7f7f4"
GRID_COLOUR = "#e0e0da"
SHADOW_COLOUR = "#c4c4bd"
TEXT_COLOUR = "#55554f"
AZIMUTH_DEG = 35.0  # camera direction, from +Z (the usual BVH facing) towards +X
ELEVATION_DEG = 24.0
MARGIN = 1.08
LABEL_BAND_PX = 26  # kept free above the figure for the clip label


@dataclass(frozen=True)
class RenderInfo:
    path: Path
    frames: int
    fps: float
    size: tuple[int, int]


def render_preview(clips: Sequence[BVH], out: str | Path, force: bool = True, **options) -> RenderInfo:
    """render_file, written atomically (`force=False` refuses an existing file)."""
    out = Path(out)
    with OutputSet.for_file(out, force=force) as files:
        infos = []
        files.write(out.name, lambda tmp: infos.append(render_file(clips, tmp, suffix=out.suffix, **options)))
        files.commit()
    return replace(infos[0], path=out)


def render_file(
    clips: Sequence[BVH],
    out: str | Path,
    fps: float | None = None,
    labels: Sequence[str] | None = None,
    size: tuple[int, int] | None = None,
    max_seconds: float | None = None,
    units: str | float = "auto",
    root: str | None = None,
    up: str | None = None,
    suffix: str | None = None,
) -> RenderInfo:
    """Render clips side by side (one panel each) to a .gif or .mp4 at `out` itself (a caller's temp
    file: `suffix` overrides its format; render_preview writes atomically).

    `fps` overrides the clips' frame rate; playback runs at that rate, divided
    by the smallest whole number that brings it under the format's limit
    (50 fps for GIF, 60 for MP4). Shorter clips hold their last pose. `size` is
    the whole image in pixels (default 360 x 360 per panel). `root` and `up`
    override the joint the camera follows and the up axis (see stick_figure)."""
    out = Path(out)
    suffix = (suffix or out.suffix).lower()
    if suffix not in FORMATS:
        raise SinMDMError(f"cannot render '{suffix or out.name}' previews: use .gif or .mp4")
    if not clips:
        raise SinMDMError("no clips to preview")
    if labels is not None and len(labels) != len(clips):
        raise SinMDMError(f"got {len(labels)} labels for {len(clips)} clips")
    if max_seconds is not None and not max_seconds > 0:
        raise SinMDMError(f"max seconds must be > 0, got {max_seconds}")
    figures = [stick_figure(clip, None if labels is None else labels[i], fps, units, root, up)
               for i, clip in enumerate(clips)]
    rate = playback_rate(max(f.fps for f in figures), FORMATS[suffix])
    seconds = max(f.seconds for f in figures)
    if max_seconds is not None:
        seconds = min(seconds, max_seconds)
    times = np.arange(max(1, round(seconds * rate))) / rate
    columns, rows = grid_shape(len(figures))
    width, height = size if size is not None else (PANEL_SIZE[0] * columns, PANEL_SIZE[1] * rows)
    width, height = int(width) + int(width) % 2, int(height) + int(height) % 2  # x264 needs even sizes
    if width < 32 or height < 32:
        raise SinMDMError(f"preview size {width}x{height} is too small")
    drawer = FrameDrawer(figures, times, (width, height), (columns, rows))
    if suffix == ".gif":
        write_gif(out, drawer.frames(), gif_durations_ms(len(times), rate), drawer.palette_inks)
    else:
        write_mp4(out, drawer.frames(), rate, (width, height))
    return RenderInfo(out, len(times), rate, (width, height))


def playback_rate(fps: float, limit: float) -> float:
    return fps / max(1, math.ceil(fps / limit - 1e-9))


def grid_shape(count: int) -> tuple[int, int]:
    columns = count if count <= 4 else math.ceil(math.sqrt(count))
    return columns, math.ceil(count / columns)


def hex_rgb(colour: str) -> np.ndarray:
    """'#rrggbb' -> RGB floats in [0, 1]."""
    return np.array([int(colour[k:k + 2], 16) / 255 for k in (1, 3, 5)])


# --------------------------------------------------------------------------- camera


def camera_axes(
    azimuth_deg: float = AZIMUTH_DEG, elevation_deg: float = ELEVATION_DEG
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Screen right, screen up and towards-the-camera unit vectors (world, Y up)."""
    a, e = math.radians(azimuth_deg), math.radians(elevation_deg)
    towards = np.array([math.cos(e) * math.sin(a), math.sin(e), math.cos(e) * math.cos(a)])
    right = np.cross([0.0, 1.0, 0.0], towards)
    right /= np.linalg.norm(right)
    return right, np.cross(towards, right), towards


@dataclass
class PanelView:
    """One clip in its panel: the sampled points and the camera that follows it."""

    figure: StickFigure
    points: np.ndarray  # (N, P, 3) metres, at the render times
    target: np.ndarray  # (N, 3) camera target: the smoothed x/z of the figure's root point, on the floor
    floor: float


def panel_view(figure: StickFigure, times: np.ndarray, rate: float) -> PanelView:
    points = figure.at(times)
    floor = float(points[..., 1].min())
    root = smooth_track(points[:, figure.root, :][:, [0, 2]], rate)
    target = np.stack([root[:, 0], np.full(len(root), floor), root[:, 1]], axis=1)
    return PanelView(figure, points, target, floor)


# --------------------------------------------------------------------------- drawing


class FrameDrawer:
    """Draws every panel once, then yields frames by updating line data."""

    def __init__(self, figures: list[StickFigure], times: np.ndarray, size: tuple[int, int], layout: tuple[int, int]):
        self.times = times
        self.size = size
        rate = 1.0 / (times[1] - times[0]) if len(times) > 1 else figures[0].fps
        self.views = [panel_view(f, times, rate) for f in figures]
        self.right, self.up, self.towards = camera_axes()
        self.colours = [CLIP_COLOURS[i % len(CLIP_COLOURS)] for i in range(len(figures))]
        self.palette_inks = [GRID_COLOUR, SHADOW_COLOUR, TEXT_COLOUR, *self.colours]
        self._build(layout)

    def _project(self, points: np.ndarray, target: np.ndarray) -> np.ndarray:
        relative = points - target
        return np.stack([relative @ self.right, relative @ self.up], axis=-1)

    def _shadow(self, view: PanelView, points: np.ndarray) -> np.ndarray:
        flat = points.copy()
        flat[..., 1] = view.floor
        return flat

    def _build(self, layout: tuple[int, int]) -> None:
        mpl_figure = import_extra("matplotlib.figure")
        backend = import_extra("matplotlib.backends.backend_agg")
        collections = import_extra("matplotlib.collections")
        lines = import_extra("matplotlib.lines")
        transforms = import_extra("matplotlib.transforms")
        width, height = self.size
        columns, rows = layout
        dpi = 100
        self.figure = mpl_figure.Figure(figsize=(width / dpi, height / dpi), dpi=dpi, facecolor=BACKGROUND)
        self.canvas = backend.FigureCanvasAgg(self.figure)

        # One scale (metres per pixel) for all panels, so sizes compare.
        panel_w, panel_h = width / columns, height / rows
        screen = [self._project(np.concatenate([v.points, self._shadow(v, v.points)], axis=1), v.target[:, None, :])
                  for v in self.views]
        half_width = max(float(np.abs(s[..., 0]).max()) for s in screen)
        spans = [(float(s[..., 1].min()), float(s[..., 1].max())) for s in screen]
        tallest = max(hi - lo for lo, hi in spans)
        band = min(LABEL_BAND_PX, panel_h / 4)
        metres_per_pixel = max(2 * half_width / panel_w, tallest / (panel_h - band), 1e-9) * MARGIN
        self.grid_step = nice_step(max(panel_w, panel_h) * metres_per_pixel / 5)
        self.grid_reach = max(panel_w, panel_h) * metres_per_pixel * 1.5

        self.panels = []
        for i, (view, (lo, hi)) in enumerate(zip(self.views, spans)):
            column, row = i % columns, i // columns
            ax = self.figure.add_axes((column / columns, 1 - (row + 1) / rows, 1 / columns, 1 / rows))
            ax.set_axis_off()
            ax.set_xlim(-panel_w / 2 * metres_per_pixel, panel_w / 2 * metres_per_pixel)
            middle = (lo + hi) / 2 + band / 2 * metres_per_pixel
            ax.set_ylim(middle - panel_h / 2 * metres_per_pixel, middle + panel_h / 2 * metres_per_pixel)
            # Grid and shadow are single NaN-separated polylines: one path each is
            # much cheaper to draw than a collection of segments.
            grid = lines.Line2D([], [], color=GRID_COLOUR, linewidth=1.0, antialiased=False, animated=True)
            shadow = lines.Line2D([], [], color=SHADOW_COLOUR, linewidth=3.0, solid_capstyle="round", animated=True)
            bones = collections.LineCollection([], linewidths=3.0, capstyle="round", joinstyle="round", animated=True)
            ax.add_line(grid)
            ax.add_line(shadow)
            ax.add_collection(bones)
            # The label is part of the static background: keep the grid out of its band
            # (after add_line, which sets the axes as clip).
            x0, y0, x1, y1 = ax.bbox.extents
            grid.set_clip_box(transforms.Bbox.from_extents(x0, y0, x1, y1 - band))
            ax.text(0.04, 0.96, view.figure.label, transform=ax.transAxes, ha="left", va="top",
                    color=self.colours[i], fontsize=11, fontweight="bold")
            self.panels.append((ax, grid, shadow, bones))
        # A progress bar rather than a clock: text costs more to draw than all the bones.
        self.progress = lines.Line2D([0, 0], [0.004, 0.004], transform=self.figure.transFigure, color=TEXT_COLOUR,
                                     linewidth=2.0, solid_capstyle="butt", animated=True)
        self.figure.add_artist(self.progress)
        self.canvas.draw()
        self.background = self.canvas.copy_from_bbox(self.figure.bbox)
        self.bone_rgb = [hex_rgb(c) for c in self.colours]
        self.background_rgb = hex_rgb(BACKGROUND)

    def _grid_segments(self, view: PanelView, frame: int) -> np.ndarray:
        centre = view.target[frame]
        step, reach = self.grid_step, self.grid_reach
        segments = []
        for axis in (0, 2):
            other = 2 - axis
            first = math.ceil((centre[axis] - reach) / step)
            for k in range(first, math.floor((centre[axis] + reach) / step) + 1):
                start, end = centre.copy(), centre.copy()
                start[axis] = end[axis] = k * step
                start[other], end[other] = centre[other] - reach, centre[other] + reach
                segments.append((start, end))
        return self._project(np.array(segments).reshape(-1, 2, 3), centre)

    @staticmethod
    def _set_polyline(line, segments: np.ndarray) -> None:
        """Show (S, 2, 2) segments as one line broken by NaNs."""
        gaps = np.full((len(segments), 1, 2), np.nan)
        xy = np.concatenate([segments, gaps], axis=1).reshape(-1, 2)
        line.set_data(xy[:, 0], xy[:, 1])

    def _draw_panel(self, index: int, frame: int) -> None:
        view = self.views[index]
        ax, grid, shadow, bones = self.panels[index]
        target = view.target[frame]
        points = view.points[frame]
        pairs = view.figure.bones
        if len(pairs):
            segments = points[pairs]  # (B, 2, 3)
            depth = (segments.mean(axis=1) - target) @ self.towards
            order = np.argsort(depth)  # far bones first, near bones drawn over them
            span = max(float(np.ptp(depth)), 1e-9)
            # Far bones fade towards the background: a depth cue for a flat projection.
            fade = ((depth.max() - depth[order]) / span * 0.5)[:, None]
            colours = self.bone_rgb[index] * (1 - fade) + self.background_rgb * fade
            bones.set_segments(self._project(segments[order], target))
            bones.set_colors(colours)
            self._set_polyline(shadow, self._project(self._shadow(view, segments), target))
        self._set_polyline(grid, self._grid_segments(view, frame))
        for artist in (grid, shadow, bones):
            ax.draw_artist(artist)

    def frames(self) -> Iterator[np.ndarray]:
        """(H, W, 4) uint8 RGBA frames (a plain copy of the canvas: slicing off alpha here costs more than drawing)."""
        total = len(self.times)
        for frame in range(total):
            self.canvas.restore_region(self.background)
            for index in range(len(self.views)):
                self._draw_panel(index, frame)
            self.progress.set_xdata([0.0, (frame + 1) / total])
            self.figure.draw_artist(self.progress)
            yield np.array(self.canvas.buffer_rgba(), copy=True)


# --------------------------------------------------------------------------- writers


def gif_durations_ms(count: int, rate: float) -> list[int]:
    """Per-frame delays: GIF stores centiseconds, so alternate (30, 40, 30 ms
    at 30 fps) to keep the average exactly 1/rate."""
    ends = np.round(np.arange(1, count + 1) * 100.0 / rate) * 10
    return [int(d) for d in np.diff(np.concatenate([[0.0], ends]))]


def _ramp_palette(background: str, inks: Sequence[str], levels: int = 16):
    """A palette image holding the background blended with each ink: every
    anti-aliased pixel of a frame is (close to) one of these colours."""
    image_module = import_extra("PIL.Image")
    bg = hex_rgb(background)
    colours = [bg]
    inks = list(dict.fromkeys(inks))  # a crowd reuses the clip colours: one ramp per colour
    levels = max(2, min(levels, 1 + 255 // max(len(inks), 1)))  # a GIF palette holds 256 colours
    for ink in inks:
        rgb = hex_rgb(ink)
        colours += [bg + (rgb - bg) * (k / (levels - 1)) for k in range(1, levels)]
    flat = (np.clip(np.array(colours), 0, 1) * 255).round().astype(np.uint8).reshape(-1)
    palette = image_module.new("P", (1, 1))
    palette.putpalette(flat.tolist() + [0] * (768 - flat.size))
    return palette


def write_gif(out: Path, frames: Iterator[np.ndarray], durations_ms: Sequence[int], inks: Sequence[str]) -> None:
    """Stream frames into `out`: only the previous frame is held, so memory does not grow with the length
    (PIL's save_all keeps every frame). Each frame is stored as its changed rectangle; a frame equal to
    the previous one extends that frame's delay instead."""
    image_module = import_extra("PIL.Image")
    gif = import_extra("PIL.GifImagePlugin")
    palette = _ramp_palette(BACKGROUND, inks)
    try:
        with open(out, "wb") as fh:
            previous: np.ndarray | None = None
            pending: tuple | None = None  # (image, offset, delay) of the frame not yet written
            for frame, delay in zip(frames, durations_ms):
                image = image_module.fromarray(frame).convert("RGB").quantize(palette=palette, dither=image_module.Dither.NONE)
                indices = np.asarray(image)
                if previous is None:
                    header, _ = gif.getheader(image, info={"loop": 0, "duration": delay})
                    fh.write(b"".join(header))
                    pending = (image, (0, 0), delay)
                else:
                    box = _changed_box(previous, indices)
                    if box is None:
                        pending = (*pending[:2], pending[2] + delay)
                        continue
                    _write_gif_frame(fh, gif, *pending)
                    pending = (image.crop(box), box[:2], delay)
                previous = indices
            if pending is not None:
                _write_gif_frame(fh, gif, *pending)
            fh.write(b";")
    except OSError as exc:
        raise SinMDMError(f"cannot write {out}: {exc.strerror or exc}") from None


def _changed_box(previous: np.ndarray, current: np.ndarray) -> tuple[int, int, int, int] | None:
    """(left, top, right, bottom) of the pixels that differ, None when none do."""
    changed = previous != current
    rows, columns = np.flatnonzero(changed.any(axis=1)), np.flatnonzero(changed.any(axis=0))
    if not len(rows):
        return None
    return int(columns[0]), int(rows[0]), int(columns[-1]) + 1, int(rows[-1]) + 1


def _write_gif_frame(fh, gif, image, offset: tuple[int, int], delay: int) -> None:
    fh.write(b"".join(gif.getdata(image, offset=offset, duration=delay)))


def write_mp4(out: Path, frames: Iterator[np.ndarray], rate: float, size: tuple[int, int]) -> None:
    imageio_ffmpeg = import_extra("imageio_ffmpeg")
    writer = imageio_ffmpeg.write_frames(
        str(out), size, fps=rate, codec="libx264", pix_fmt_in="rgba", pix_fmt_out="yuv420p", quality=None, macro_block_size=2,
        ffmpeg_log_level="error", output_params=["-crf", "23", "-preset", "veryfast", "-f", "mp4", "-movflags", "+faststart"],
    )
    try:
        writer.send(None)
        for frame in frames:
            writer.send(np.ascontiguousarray(frame))
    except (OSError, RuntimeError) as exc:
        raise SinMDMError(f"cannot write {out}: {exc}") from None
    finally:
        writer.close()
