"""Production skeleton layouts derived in code from the shared clips (never copied):
a static reference root above the hips, a Z-up export, a 0-channel `Armature`
root, and the same motion in other units. Each keeps the motion exactly, so a
model of the derived clip should behave like one of the original."""

from __future__ import annotations

import numpy as np

from sinmdm.runtime.animation import Animation, animation_from_bvh, animation_to_bvh
from sinmdm.runtime.bvh import BVH, Skeleton

SIX_ZXY = ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
# Y-up to Z-up: +90 degrees about X (y -> z, z -> -y), as Blender's exporter sees the world.
Y_TO_Z = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def _with_new_root(bvh: BVH, name: str, channels: tuple[str, ...], every_joint: tuple[str, ...] | None) -> BVH:
    animation = animation_from_bvh(bvh)
    old = bvh.skeleton
    parents = np.concatenate([[-1], np.where(old.parents < 0, 0, old.parents + 1)])
    joint_channels = tuple(every_joint or c for c in old.channels)
    skeleton = Skeleton(
        names=(name,) + old.names,
        parents=parents,
        offsets=np.concatenate([np.zeros((1, 3)), old.offsets]),
        channels=(channels,) + joint_channels,
        end_sites=tuple((p + 1, o) for p, o in old.end_sites),
    )
    frames = animation.frames
    identity = np.broadcast_to(np.eye(3), (frames, 1, 3, 3))
    rotations = np.concatenate([identity, animation.rotations], axis=1)
    translations = np.concatenate([np.zeros((frames, 1, 3)), animation.translations], axis=1)
    return animation_to_bvh(Animation(skeleton, rotations, translations, animation.fps))


def with_static_root(bvh: BVH, name: str = "joint_Root") -> BVH:
    """A static reference root at the floor origin, 6 channels on every joint, ZXY:
    the hips below it carry the motion (the layout of many engine exports)."""
    return _with_new_root(bvh, name, SIX_ZXY, SIX_ZXY)


def with_armature(bvh: BVH, name: str = "Armature") -> BVH:
    """A 0-channel dummy root above the original root."""
    return _with_new_root(bvh, name, (), None)


def z_up(bvh: BVH) -> BVH:
    """The same motion in a Z-up world: every offset, translation and local rotation
    conjugated by the Y-to-Z rotation, so world positions are rotated and nothing else."""
    animation = animation_from_bvh(bvh)
    old = bvh.skeleton
    skeleton = Skeleton(
        names=old.names,
        parents=old.parents,
        offsets=old.offsets @ Y_TO_Z.T,
        channels=old.channels,
        end_sites=tuple((p, None if o is None else Y_TO_Z @ o) for p, o in old.end_sites),
    )
    matrices = Y_TO_Z @ animation.rotations @ Y_TO_Z.T
    translations = animation.translations @ Y_TO_Z.T
    return animation_to_bvh(Animation(skeleton, matrices, translations, animation.fps))


def scaled(bvh: BVH, factor: float) -> BVH:
    """The same motion with lengths multiplied by `factor` (0.01: cm -> m)."""
    old = bvh.skeleton
    skeleton = Skeleton(
        names=old.names,
        parents=old.parents,
        offsets=old.offsets * factor,
        channels=old.channels,
        end_sites=tuple((p, None if o is None else o * factor) for p, o in old.end_sites),
    )
    values = bvh.values.copy()
    for j, channels in enumerate(old.channels):
        start = int(old.channel_starts[j])
        for i, channel in enumerate(channels):
            if channel.endswith("position"):
                values[:, start + i] *= factor
    return BVH(skeleton, bvh.frame_time, values)


LAYOUTS = {
    "static-root": with_static_root,
    "z-up": z_up,
    "static-root-z-up": lambda bvh: z_up(with_static_root(bvh)),
    "armature": with_armature,
}
