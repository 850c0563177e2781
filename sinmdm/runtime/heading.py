"""The heading frame: an optional graph space in which the trajectory joint's rotation
and velocity are seen from the character's own heading, plus one channel for the
heading's rate of turn.

The paper's features hold the trajectory joint's rotation and velocity in the world
(its parent's frame). A clip that walks a circle then shows the network a different
heading in every window, and what repeats (turning left at 30 deg/s) is nowhere a
local pattern: measured on the Mixamo walk, samples of one window turn at 2 deg/s
against the clip's 30, and long ones spin where windows of different headings meet
(BENCHMARKS.md, "Turning"). In the heading frame the yaw about the up axis is taken
out of the rotation and the velocity and kept as its per-second rate, so a turn is a
pattern like any other; it is integrated back, from the clip's start heading, when
features leave the graph's space.

Angles are about the trajectory joint's parent-frame up axis (`codec.height_axis`),
positive by the right-hand rule; the heading is the yaw of the trajectory joint's
`forward` axis (the local axis the clip travels along, or its most horizontal one).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import SinMDMError
from .rotations import axis_matrix, matrix_to_6d, sixd_to_matrix

ROOT_FRAMES = ("world", "heading")
MOVING_SPEED = 0.1  # m/s: below this the root stands and its direction of travel means nothing


def trajectory_rotation(codec):
    """The feature block of the trajectory joint's rotation, None where it has none (no heading)."""
    if codec.trajectory_joint is None:
        return None
    joint = codec.skeleton.names[codec.trajectory_joint]
    return next((b for b in codec.layout.blocks if b.kind == "rotation" and b.joint == joint), None)


@dataclass(frozen=True)
class HeadingFrame:
    rotation: tuple[int, ...]  # the six feature channels of the trajectory joint's 6D rotation
    velocity: tuple[int, int]  # its two horizontal velocity channels (d<h1>, d<h2>)
    horizontal: tuple[int, int]  # the parent-frame axes those velocities are along
    up: int  # the parent-frame up axis
    forward: np.ndarray  # (3,) the trajectory joint's local axis whose yaw is the heading
    fps: float
    start: float = 0.0  # radians: the clip's heading at its first frame

    @classmethod
    def of(cls, codec, forward, start: float = 0.0) -> "HeadingFrame":
        rotation = trajectory_rotation(codec)
        dx, _, dz = codec.layout.indices(("root",))
        return cls(tuple(range(rotation.start, rotation.stop)), (int(dx), int(dz)), codec.horizontal_axes,
                   codec.height_axis, np.asarray(forward, dtype=np.float64), float(codec.fps), float(start))

    def to_dict(self) -> dict:
        return {"forward": [float(v) for v in self.forward], "start": self.start}

    def headings(self, features: np.ndarray) -> np.ndarray:
        """(..., T) radians, unwrapped along T: the yaw of the forward axis."""
        facing = sixd_to_matrix(features[..., list(self.rotation)].reshape(features.shape[:-1] + (6,))) @ self.forward
        return np.unwrap(yaw(facing, self.up), axis=-1)

    def _turned(self, features: np.ndarray, angles: np.ndarray) -> np.ndarray:
        """Features with the trajectory joint's rotation and velocity turned by `angles` (..., T)."""
        turn = axis_matrix(self.up, angles)
        out = features.astype(np.float64, copy=True)
        rotation = sixd_to_matrix(out[..., list(self.rotation)])
        out[..., list(self.rotation)] = matrix_to_6d(turn @ rotation)
        velocity = np.zeros(features.shape[:-1] + (3,))
        velocity[..., list(self.horizontal)] = out[..., list(self.velocity)]
        out[..., list(self.velocity)] = np.einsum("...ab,...b->...a", turn, velocity)[..., list(self.horizontal)]
        return out

    def to_graph(self, features: np.ndarray) -> np.ndarray:
        """(..., T, F) features -> (..., T, F + 1): heading taken out, its rate (rad/s) appended
        (frame 0 repeats frame 1's, as the velocities do)."""
        heading = self.headings(features)
        rate = np.diff(heading, axis=-1) * self.fps
        rate = np.concatenate([rate[..., :1] if rate.shape[-1] else np.zeros(rate.shape[:-1] + (1,)), rate], axis=-1)
        return np.concatenate([self._turned(features, -heading), rate[..., None]], axis=-1)

    def to_features(self, x: np.ndarray, start: float | np.ndarray | None = None) -> np.ndarray:
        """(..., T, F + 1) -> (..., T, F): the heading integrated from `start` (default the
        clip's; or one per motion, shape (...,)) over the rates of frames 1..T-1 and put back."""
        rate = x[..., -1].astype(np.float64) / self.fps
        first = np.asarray(self.start if start is None else start, dtype=np.float64)[..., None]
        heading = first + np.concatenate([np.zeros(rate.shape[:-1] + (1,)), np.cumsum(rate[..., 1:], axis=-1)], axis=-1)
        return self._turned(x[..., :-1], heading)


def yaw(vectors: np.ndarray, up: int) -> np.ndarray:
    """(..., 3) -> (...,) radians about axis `up`, by the right-hand rule (as axis_matrix turns)."""
    u, v = (up + 1) % 3, (up + 2) % 3  # axis_matrix(up, a) turns u towards v by a
    return np.arctan2(vectors[..., v], vectors[..., u])


def moving_axis(rotations: np.ndarray, velocity: np.ndarray, up: int) -> np.ndarray | None:
    """(3,) the local axis of a joint ((T, 3, 3) rotations in its parent's frame, (T, 3)
    velocities in m/s) along which it travels; None for a joint that stands."""
    velocity = velocity.copy()
    velocity[:, up] = 0.0
    moving = np.linalg.norm(velocity, axis=-1) > MOVING_SPEED
    if moving.mean() < 0.2:
        return None
    local = np.einsum("tba,tb->a", rotations[moving], velocity[moving])
    return local / np.linalg.norm(local) if np.linalg.norm(local) > 1e-9 else None


def horizontal_axis(rotations: np.ndarray, up: int) -> np.ndarray:
    """(3,) the local axis of a joint ((T, 3, 3) rotations) that lies the most horizontal."""
    world = np.einsum("tab,kb->tka", rotations, np.eye(3))
    return np.eye(3)[int(np.argmin(np.abs(world[..., up]).mean(axis=0)))]


def travel_axis(rotations: np.ndarray, velocity: np.ndarray, up: int) -> np.ndarray:
    """The axis a joint travels along (`moving_axis`), or for one that stands its most horizontal."""
    axis = moving_axis(rotations, velocity, up)
    return horizontal_axis(rotations, up) if axis is None else axis


def clip_heading_frame(codec, features: np.ndarray) -> HeadingFrame:
    """The heading frame of a clip's (T, F) features: its travel axis and start heading."""
    features = np.asarray(features, dtype=np.float64)
    block = trajectory_rotation(codec)
    rotations = sixd_to_matrix(features[:, block.start : block.stop])
    dx, _, dz = codec.layout.indices(("root",))
    velocity = np.zeros((len(features), 3))
    velocity[:, list(codec.horizontal_axes)] = features[:, [dx, dz]] * codec.fps
    frame = HeadingFrame.of(codec, travel_axis(rotations, velocity, codec.height_axis))
    return HeadingFrame.of(codec, frame.forward, float(frame.headings(features)[0]))


# --------------------------------------------------------------------------- guides
KNOWN = 0.999  # a keep weight at or above this keeps the channel exactly (the applications' ramps are below)


def _wrapped(angle: np.ndarray) -> np.ndarray:
    return (angle + np.pi) % (2 * np.pi) - np.pi


def check_keep(frame: HeadingFrame, keep: np.ndarray | None) -> None:
    """A velocity kept without the rotation it is turned by cannot be kept in the heading frame."""
    if keep is None:
        return
    keep = np.asarray(keep, dtype=np.float64)
    rotation = keep[..., list(frame.rotation), :].min(axis=-2)
    if any((keep[..., c, :] > rotation + 1e-9).any() for c in frame.velocity):
        raise SinMDMError("this model sees motion from the character's heading (trained with --root-frame heading): "
                          "a path without the reference's rotations cannot guide it; give a reference on the model's "
                          "skeleton, or use a model trained with --root-frame world")


class GuidedHeading:
    """An application's guide in the heading frame. A channel of the graph is kept where
    what it is made of is kept: the turned rotation where the trajectory joint's rotation
    is, the turned velocity where that and the world velocity are, the rate of turn where
    the rotation is kept on this frame and the one before. After sampling, `starts` turns
    each sample so the heading meets the reference's on the first kept frame, and spreads
    what it misses on each later kept frame over the frames before it (the heading's
    `land_on_reference`)."""

    def __init__(self, frame: HeadingFrame, reference: np.ndarray, keep: np.ndarray | None, region: np.ndarray | None):
        self.frame = frame
        check_keep(frame, keep)
        features = np.moveaxis(np.asarray(reference, dtype=np.float64), -2, -1)  # (..., T, F)
        self.headings = frame.headings(features)  # (..., T): only wrapped differences of these count
        self.faces = np.abs(features[..., 0, list(frame.rotation)]).sum(axis=-1) > 0  # (...,) a pose at frame 0
        self.reference = np.nan_to_num(np.moveaxis(frame.to_graph(features), -1, -2))  # (..., G, T)
        self.keep = None if keep is None else self._channels(np.asarray(keep, dtype=np.float64))
        self.region = None if region is None else self._channels(np.asarray(region, dtype=np.float64))
        rotation = (np.zeros(features.shape[-2]) if keep is None
                    else np.asarray(keep, dtype=np.float64)[..., list(frame.rotation), :].min(axis=-2))
        self.known = rotation >= KNOWN  # (..., T) frames whose heading the reference fixes

    def _channels(self, mask: np.ndarray) -> np.ndarray:
        """(..., F, T) feature mask -> (..., F + 1, T) graph mask."""
        f = self.frame
        rotation = mask[..., list(f.rotation), :].min(axis=-2)
        out = np.concatenate([mask, np.zeros(mask.shape[:-2] + (1, mask.shape[-1]))], axis=-2)
        for c in f.velocity:
            out[..., c, :] = np.minimum(mask[..., c, :], rotation)
        before = np.concatenate([rotation[..., :1] * 0.0, rotation[..., :-1]], axis=-1)
        out[..., -1, :] = np.minimum(rotation, before)
        return out

    def starts(self, x: np.ndarray) -> np.ndarray:
        """x (N, G, T) sampled in the graph's space (the guide's frames), its rates changed in
        place where headings are landed; returns (N,) start headings."""
        rate = x[:, -1, :].astype(np.float64) / self.frame.fps
        count, frames = rate.shape

        def fitted(a: np.ndarray) -> np.ndarray:
            a = a[..., :frames]
            pad = np.zeros(a.shape[:-1] + (frames - a.shape[-1],), dtype=a.dtype)
            return np.broadcast_to(np.concatenate([a, pad], axis=-1), (count, frames))

        known, reference = fitted(self.known), fitted(self.headings)
        starts = np.full(count, self.frame.start)
        for n in range(count):
            kept = np.flatnonzero(known[n])
            if not len(kept):
                if np.broadcast_to(self.faces, (count,))[n]:
                    starts[n] = reference[n, 0]  # facing as the reference starts (a harmonized clip)
                continue
            heading = np.concatenate([[0.0], np.cumsum(rate[n, 1:])])
            starts[n] = reference[n, kept[0]] - heading[kept[0]]
            for previous, k in zip(kept[:-1], kept[1:]):
                if k == previous + 1:
                    continue
                miss = _wrapped(reference[n, k] - (starts[n] + heading[k]))
                rate[n, previous + 1 : k + 1] += miss / (k - previous)
                heading = np.concatenate([[0.0], np.cumsum(rate[n, 1:])])
        x[:, -1, :] = (rate * self.frame.fps).astype(x.dtype)
        return starts


def close_the_turn(x: np.ndarray, fps: float) -> np.ndarray:
    """x (N, G, T) a loop in the graph's space (frame 0's rate is the step across the wrap),
    with its turn per cycle rounded to whole turns, the difference spread evenly over the
    cycle's rates, so the facing at the wrap flows into the first frame's. A walk in a circle
    loops as a circle; a motion that turns a little loops facing one way."""
    rate = x[:, -1, :].astype(np.float64)
    total = rate.sum(axis=-1) / fps
    missing = 2 * np.pi * np.round(total / (2 * np.pi)) - total
    out = x.copy()
    out[:, -1, :] = (rate + (missing * fps / rate.shape[-1])[:, None]).astype(x.dtype)
    return out
