"""Previews of BVH motion: stick-figure GIF/MP4 renders, a self-contained HTML
viewer, and glTF (GLB) export.

This module holds what every preview shares: the stick figure of a clip (joint
and End Site world positions in metres, Y up, sampled at any time) and the lazy
import of the optional libraries. Whatever the clip's layout, the figure is the
same: static joints above the one that carries the character (a `joint_Root` at
the floor, an `Armature` node) are left out, the camera follows that joint, and a
Z-up clip is turned into the Y-up display frame (see runtime/rig.py). The public
functions live in the submodules and are re-exported lazily, so importing this
package costs only numpy.
"""

from __future__ import annotations

import importlib
import math
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any

import numpy as np

from ..runtime.errors import SinMDMError

if TYPE_CHECKING:
    from ..runtime.bvh import BVH

EXTRA_MISSING = "previews need the preview extra: pip install 'sinmdm[preview]'"

# World up axis (rig.py's index) -> the rotation that brings it to +Y, right-handed:
# Z-up is turned -90 degrees about X, (x, y, z) -> (x, z, -y), so Blender's -Y
# forward faces +Z, the usual BVH facing.
UP_TO_Y = {
    1: np.eye(3),
    2: np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]),
}
CAMERA_SMOOTHING_S = 0.5  # sigma of the Gaussian that smooths the root track a camera follows
# One colour per clip, in order; the renders and the viewer use the same ones.
CLIP_COLOURS = ("#e4572e", "#2e86de", "#17a673", "#8e44ad", "#f39c12", "#c0392b", "#16a085", "#2c3e50")

_EXPORTS = {
    "render_preview": "render",
    "write_viewer": "viewer",
    "viewer_html": "viewer",
    "bvh_to_glb": "gltf",
    "write_glb": "gltf",
    "read_glb": "gltf",
}

__all__ = [
    "CLIP_COLOURS", "EXTRA_MISSING", "UP_TO_Y", "StickFigure", "import_extra", "nice_step", "smooth_track",
    "stick_figure", *_EXPORTS,
]


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        return getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def import_extra(name: str) -> ModuleType:
    """Import one of the preview extra's libraries, or explain how to get it."""
    try:
        return importlib.import_module(name)
    except ImportError:
        raise SinMDMError(EXTRA_MISSING) from None


@dataclass(frozen=True)
class StickFigure:
    """A clip as points and bones: joints first, then End Sites (the clip's fixed
    reference joints and their End Sites left out)."""

    label: str
    fps: float
    points: np.ndarray  # (T, P, 3) world positions in metres, Y up
    parents: np.ndarray  # (P,) the point each point hangs from, -1 for a root
    root: int  # the point the camera follows: the joint that carries the character
    names: tuple[str, ...] = ()  # (P,) joint names, then "<parent>_end" for End Sites

    @property
    def frames(self) -> int:
        return self.points.shape[0]

    @property
    def seconds(self) -> float:
        return self.frames / self.fps

    @property
    def bones(self) -> np.ndarray:
        """(B, 2) point indices (child, parent) of every bone."""
        children = np.flatnonzero(self.parents >= 0)
        return np.stack([children, self.parents[children]], axis=1)

    def at(self, times: np.ndarray) -> np.ndarray:
        """(len(times), P, 3) positions at `times` seconds, interpolated
        linearly between frames and held at the ends."""
        position = np.clip(np.asarray(times, dtype=np.float64) * self.fps, 0.0, self.frames - 1)
        before = np.floor(position).astype(np.int64)
        after = np.minimum(before + 1, self.frames - 1)
        weight = (position - before)[:, None, None]
        return self.points[before] * (1.0 - weight) + self.points[after] * weight


def stick_figure(
    bvh: BVH,
    label: str | None = None,
    fps: float | None = None,
    units: str | float = "auto",
    root: str | None = None,
    up: str | None = None,
) -> StickFigure:
    """World positions of a clip's joints and End Sites, in metres, Y up.

    `fps` overrides the clip's own frame rate (for files with a wrong Frame Time);
    `root` (a joint name) and `up` ('y', 'z' or 'auto') override what
    runtime/rig.py detects. The static joints above the trajectory joint, and
    every bone to them, are left out; a Z-up clip is turned to stand along +Y."""
    from ..runtime.animation import Animation, animation_from_bvh, nominal_fps
    from ..runtime.features import unit_scale
    from ..runtime.kinematics import end_site_positions, forward_kinematics
    from ..runtime.rig import analyse_rig

    if bvh.frames == 0:
        raise SinMDMError(f"{bvh.path or 'the clip'} has no frames to show")
    if fps is not None and not (np.isfinite(fps) and fps > 0):
        raise SinMDMError(f"frame rate must be a number > 0, got {fps}")
    skeleton = bvh.skeleton
    rate = float(fps) if fps is not None else nominal_fps(bvh.frame_time)
    scale = unit_scale(skeleton, units)
    animation = animation_from_bvh(bvh)
    rig = analyse_rig(Animation(skeleton, animation.rotations, animation.translations, rate), scale, root, up)
    rotations, positions = forward_kinematics(animation.rotations, animation.translations, skeleton.parents)
    ends = end_site_positions(rotations, positions, skeleton.end_sites)
    parents = np.concatenate([skeleton.parents, [p for p, _ in skeleton.end_sites]]).astype(np.int64)
    names = list(skeleton.names) + [f"{skeleton.names[p]}_end" for p, _ in skeleton.end_sites]
    points = np.concatenate([positions, ends], axis=1) * scale @ UP_TO_Y[rig.up_axis].T

    # Leave out the fixed joints (a frame of reference only) and their End Sites;
    # a point that hung from one becomes a root, so no bone reaches them.
    fixed = np.zeros(len(parents), dtype=bool)
    fixed[list(rig.fixed_joints)] = True
    fixed[skeleton.num_joints:] = fixed[parents[skeleton.num_joints:]]
    keep = np.flatnonzero(~fixed)
    new_index = np.full(len(parents), -1, dtype=np.int64)
    new_index[keep] = np.arange(len(keep))
    kept_parents = np.where(parents[keep] >= 0, new_index[np.maximum(parents[keep], 0)], -1)
    follow = rig.trajectory_joint if rig.trajectory_joint is not None else skeleton.roots[0]
    if label is None:
        label = "clip" if bvh.path is None else Path(bvh.path).stem
    return StickFigure(
        label=label,
        fps=rate,
        points=np.ascontiguousarray(points[:, keep]),
        parents=kept_parents,
        root=int(new_index[follow]),
        names=tuple(names[k] for k in keep),
    )


def smooth_track(track: np.ndarray, rate: float, sigma_seconds: float = CAMERA_SMOOTHING_S) -> np.ndarray:
    """Gaussian smoothing of a (N, K) track sampled at `rate` per second, with
    the ends held: a zero-lag path for a camera to follow."""
    sigma = sigma_seconds * rate
    if sigma < 0.5 or len(track) < 2:
        return np.array(track, dtype=np.float64)
    radius = int(3 * sigma)
    kernel = np.exp(-0.5 * (np.arange(-radius, radius + 1) / sigma) ** 2)
    kernel /= kernel.sum()
    padded = np.pad(np.asarray(track, dtype=np.float64), [(radius, radius), (0, 0)], mode="edge")
    return np.stack([np.convolve(padded[:, k], kernel, mode="valid") for k in range(padded.shape[1])], axis=1)


def nice_step(length: float) -> float:
    """1, 2 or 5 times a power of ten, closest to `length` (a grid spacing)."""
    power = 10.0 ** math.floor(math.log10(length))
    return min((m * power for m in (1.0, 2.0, 5.0, 10.0)), key=lambda s: abs(math.log(s / length)))
