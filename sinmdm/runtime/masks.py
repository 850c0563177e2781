"""Masks over (features, frames) built by name from a FeatureLayout: which parts of a
reference the sampler keeps (composition) or harmonizes (ILVR). 1 = reference."""

from __future__ import annotations

import numpy as np

from .bvh import Skeleton
from .errors import SinMDMError
from .features import MotionCodec

JOINT_SETS = ("upper-body", "lower-body")


def frame_ramp(frames: int, keep: list[tuple[int, int]], ramp: int) -> np.ndarray:
    """(frames,) weights: 1 inside the kept ranges [start, stop), falling linearly to 0
    over `ramp` frames at each border that faces generated frames (ramps lie inside
    the kept range, as in the reference implementation)."""
    weights = np.zeros(frames)
    for start, stop in keep:
        start, stop = max(0, start), min(frames, stop)
        if stop <= start:
            continue
        span = np.ones(stop - start)
        r = min(ramp, (stop - start) // 2)
        if r > 0:
            rise = (np.arange(r) + 1) / (r + 1)
            if start > 0:
                span[:r] = np.minimum(span[:r], rise)
            if stop < frames:
                span[-r:] = np.minimum(span[-r:], rise[::-1])
        weights[start:stop] = np.maximum(weights[start:stop], span)
    return weights


def subtree(skeleton: Skeleton, name: str) -> set[str]:
    root = skeleton.index(name)
    members = {root}
    for j in range(root + 1, skeleton.num_joints):
        if int(skeleton.parents[j]) in members:
            members.add(j)
    return {skeleton.names[j] for j in members}


def body_halves(codec: MotionCodec) -> tuple[set[str], set[str]]:
    """(upper, lower) joint names for any humanoid-like skeleton: the lower body is the
    pelvis (the trajectory joint) and every chain that leaves it downwards in the rest
    pose; the upper body is everything else."""
    from .animation import rest_positions

    skeleton = codec.skeleton
    pelvis = codec.trajectory_joint if codec.trajectory_joint is not None else skeleton.roots[0]
    rest = rest_positions(skeleton)
    lower = {skeleton.names[pelvis]}
    for child in skeleton.children(pelvis):
        names = subtree(skeleton, skeleton.names[child])
        heights = [rest[skeleton.index(n), codec.up_axis] for n in names]
        if np.mean(heights) < rest[pelvis, codec.up_axis]:
            lower |= names
    upper = set(skeleton.names) - lower
    if len(lower) == 1 or not upper:
        raise SinMDMError("cannot tell upper from lower body on this skeleton: name the joints with --joints or --subtree")
    return upper, lower


def joint_names(codec: MotionCodec, joints: str | None = None, subtree_of: str | None = None) -> set[str]:
    """Resolve --joints (upper-body, lower-body or comma-separated names) and --subtree."""
    names: set[str] = set()
    if joints:
        if joints in JOINT_SETS:
            upper, lower = body_halves(codec)
            names |= upper if joints == "upper-body" else lower
        else:
            for name in (n.strip() for n in joints.split(",")):
                codec.skeleton.index(name)  # raises, naming an unknown joint
                names.add(name)
    if subtree_of:
        names |= subtree(codec.skeleton, subtree_of)
    return names


def feature_channels(codec: MotionCodec, names: set[str], with_root: bool) -> np.ndarray:
    """Feature indices of the joints (rotation, translation, contact blocks) and, if
    asked, the root trajectory (dx, y, dz)."""
    layout = codec.layout
    channels = [layout.indices(("rotation", "translation", "contact"), names)]
    if with_root:
        channels.append(layout.indices(("root",)))
    return np.unique(np.concatenate(channels)).astype(np.int64)


def trajectory_channels(codec: MotionCodec, with_heading: bool = True) -> np.ndarray:
    """x/z motion of the root (dx, dz) and, when available, its rotation (heading)."""
    layout = codec.layout
    roots = [b for b in layout.blocks if b.kind == "root"]
    if not roots:
        raise SinMDMError("this model's skeleton has no root translation: trajectory control is not possible")
    block = roots[0]
    channels = [block.start, block.stop - 1]  # dx, dz
    if with_heading:
        channels += list(layout.indices(("rotation",), {block.joint}))
    return np.asarray(sorted(channels), dtype=np.int64)


def has_body_halves(codec: MotionCodec) -> bool:
    try:
        body_halves(codec)
    except SinMDMError:
        return False
    return True


def units_warning_for(codec: MotionCodec) -> str | None:
    """A warning naming --units when a humanoid-shaped figure has an implausible size."""
    from .rig import units_warning

    return units_warning(codec.size, has_body_halves(codec))
