"""Editing at inference time with the trained model unchanged (reference notes,
section 5): in-betweening, expansion, keyframes, joint and trajectory control,
harmonization (whole clip = style transfer, or a pasted portion). Each `plan_*`
turns a reference clip and options into what the sampler needs: a Guide, the
output length, and the root's start position."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from .bvh import read_bvh
from .errors import OptionError, SinMDMError
from .animation import Animation, animation_from_bvh, nominal_fps
from .bvh import BVH
from .features import build_codec, check_same_skeleton, check_source_fps, skeleton_size
from .generate import GenerationResult, generate
from .masks import feature_channels, frame_ramp, joint_names, trajectory_channels
from .model import MotionModel
from .options import SamplingOptions, check_length, check_number, check_whole
from .sampler import Guide, sample_features

INBETWEEN_KEEP = 0.25
INBETWEEN_RAMP = 10
EXPAND_SHARE = 0.15
EXPAND_RAMP = 6
HARMONIZE_BORDER = 10
# A reference outside this frame rate has a Frame Time written wrong (as `inspect` warns):
# refused unless its rate is given (source_fps).
PLAUSIBLE_FPS = (5.0, 1000.0)


@dataclass
class Reference:
    path: Path
    features: np.ndarray  # (frames, F) at the model's frame rate
    start: np.ndarray  # (x, z) metres

    @property
    def frames(self) -> int:
        return self.features.shape[0]


@dataclass
class Plan:
    guide: Guide
    frames: int
    start: np.ndarray
    fix_root: tuple[int, int] | None = None  # (gap start, gap stop): land the kept end on the reference's path
    reference: Reference | None = None


def _matching_scale(model: MotionModel, skeleton) -> float | None:
    """The reference's own metres-per-unit when it was saved in other units than the
    training clip (same joints, offsets scaled), else None."""
    ratio = skeleton_size(skeleton) / skeleton_size(model.codec.skeleton)
    if 0.5 < ratio < 2.0:
        return None
    return model.codec.scale / ratio


def reference_fps(bvh: BVH, path: str | Path, source_fps: float | None = None) -> float:
    """The clip's frame rate: `source_fps` when given, else its Frame Time's, which must be plausible."""
    if source_fps is not None:
        return check_source_fps(source_fps)
    low, high = PLAUSIBLE_FPS
    if not 1.0 / high <= bvh.frame_time <= 1.0 / low:
        raise OptionError("source_fps", f"{path} has a frame time of {bvh.frame_time:g} s, outside {low:g}..{high:g} "
                                        "fps: it looks wrong; give the clip's frame rate")
    return nominal_fps(bvh.frame_time)


def _read_reference(model: MotionModel, path: str | Path, source_fps: float | None, force: bool) -> tuple[BVH, float]:
    """The clip and its frame rate, its length at the model's rate checked before any work."""
    bvh = read_bvh(path)
    fps = reference_fps(bvh, path, source_fps)
    check_length(max(math.ceil(bvh.frames * model.codec.fps / fps), 1), model.codec.fps, force)
    return bvh, fps


def load_reference(model: MotionModel, path: str | Path, source_fps: float | None = None, force: bool = False) -> Reference:
    """A reference clip on the model's skeleton (names and hierarchy checked), at the
    model's frame rate and units."""
    bvh, fps = _read_reference(model, path, source_fps, force)
    check_same_skeleton(model.codec.skeleton, bvh.skeleton, what=f"reference {path}")
    animation = animation_from_bvh(bvh)
    scale = _matching_scale(model, bvh.skeleton)
    if scale is not None:
        animation = Animation(model.codec.skeleton, animation.rotations,
                              animation.translations * (scale / model.codec.scale), fps)
    else:
        animation = Animation(model.codec.skeleton, animation.rotations, animation.translations, fps)
    features = model.codec.encode(animation)
    start = model.codec.start_position(animation)
    if features.shape[0] < 2:
        raise SinMDMError(f"reference {path} is too short ({features.shape[0]} frame at {model.codec.fps:g} fps)")
    return Reference(Path(path), features.astype(np.float64), start)


def load_trajectory(model: MotionModel, path: str | Path, source_fps: float | None = None, force: bool = False) -> Reference:
    """Only the root path matters for trajectory control, so any skeleton will do:
    its trajectory joint, in its own units and axes, at the model's rate."""
    bvh, fps = _read_reference(model, path, source_fps, force)
    if bvh.skeleton.same_hierarchy(model.codec.skeleton):
        return load_reference(model, path, fps, force)
    codec = build_codec(bvh, fps=model.codec.fps, contacts=[], source_fps=fps)
    if codec.trajectory_joint is None:
        raise SinMDMError(f"trajectory reference {path} has no joint with position channels")
    own = codec.encode(bvh, source_fps=fps)[:, codec.layout.indices(("root",))]
    start = codec.start_position(bvh, source_fps=fps)
    # A Z-up path on a Y-up model (or the reverse): same floor plan, not its mirror image.
    flip = codec.handedness * model.codec.handedness
    own[:, 2] *= flip
    start = start * [1.0, flip]
    features = np.zeros((own.shape[0], model.features))
    features[:, model.codec.layout.indices(("root",))] = own
    return Reference(Path(path), features, start)


def load_control_reference(model: MotionModel, path: str | Path, source_fps: float | None = None,
                           joints: str | None = None, subtree: str | None = None, trajectory: bool = False,
                           force: bool = False) -> Reference:
    """What joint/trajectory control needs: a path alone may come from any skeleton."""
    load = load_trajectory if trajectory and not (joints or subtree) else load_reference
    return load(model, path, source_fps, force)


def _full(model: MotionModel, reference: Reference, frames: int, offset: int = 0) -> np.ndarray:
    """The reference's features placed at `offset` in a (F, frames) array."""
    out = np.zeros((model.features, frames))
    stop = min(frames, offset + reference.frames)
    out[:, offset:stop] = reference.features[: stop - offset].T
    return out


def plan_inbetween(model: MotionModel, reference: Reference, keep_start: float = INBETWEEN_KEEP,
                   keep_end: float = INBETWEEN_KEEP, ramp: int = INBETWEEN_RAMP) -> Plan:
    """Keep the first and last shares of the reference, generate the frames between."""
    check_number("keep_start", keep_start, high=1.0, below_high=True)
    check_number("keep_end", keep_end, high=1.0, below_high=True)
    check_whole("ramp", ramp)
    frames = reference.frames
    head, tail = int(round(keep_start * frames)), int(round(keep_end * frames))
    if head + tail >= frames:
        raise SinMDMError("nothing left to generate: the kept start and end cover the whole reference")
    keep = frame_ramp(frames, [(0, head), (frames - tail, frames)], ramp)
    guide = Guide(reference=_full(model, reference, frames), keep=np.broadcast_to(keep, (model.features, frames)))
    blended = np.flatnonzero(keep < 1.0)  # the gap and its ramps: where root velocities were generated
    return Plan(guide, frames, reference.start, fix_root=(int(blended[0]) - 1, int(blended[-1]) + 1), reference=reference)


def plan_expand(model: MotionModel, reference: Reference, before: float = EXPAND_SHARE,
                after: float = EXPAND_SHARE, ramp: int = EXPAND_RAMP, force: bool = False) -> Plan:
    """Generate new frames before and after the reference (shares of its length; the
    result capped as `check_length` unless `force`)."""
    check_number("before", before)
    check_number("after", after)
    check_whole("ramp", ramp)
    check_length(math.ceil((before + after + 1) * reference.frames), model.codec.fps, force)
    ahead, behind = int(round(before * reference.frames)), int(round(after * reference.frames))
    frames = ahead + reference.frames + behind
    keep = frame_ramp(frames, [(ahead, ahead + reference.frames)], ramp)
    guide = Guide(reference=_full(model, reference, frames, ahead), keep=np.broadcast_to(keep, (model.features, frames)))
    return Plan(guide, frames, reference.start, reference=reference)


def parse_keyframes(text: str) -> list[int]:
    """'0,30,90' as frame numbers."""
    try:
        return [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise OptionError("keyframes", f"takes comma-separated frame numbers, got '{text}'") from None


def default_keyframes(model: MotionModel, reference: Reference, every: int | None = None) -> list[int]:
    """Every `every`-th frame of the reference (default: one a second at the model's rate)."""
    step = int(round(model.codec.fps)) if every is None else check_whole("every", every, 1)
    return list(range(0, reference.frames, max(step, 1)))


def plan_keyframes(model: MotionModel, reference: Reference, keyframes: list[int], hold: int = 0) -> Plan:
    """Keep the reference's poses at sparse frames (each held for `hold` frames either side)."""
    frames = reference.frames
    check_whole("hold", hold)
    bad = [k for k in keyframes if not 0 <= k < frames]
    if bad:
        raise OptionError("keyframes", f"frame {bad[0]} is outside the reference (0..{frames - 1})")
    if not keyframes:
        raise OptionError("keyframes", "no keyframes given")
    keep = np.zeros(frames)
    for k in keyframes:
        keep[max(0, k - hold) : k + hold + 1] = 1.0
    # Root velocities are only meaningful over consecutive kept frames: keep pose and height.
    mask = np.broadcast_to(keep, (model.features, frames)).copy()
    root = model.codec.layout.indices(("root",))
    if len(root):
        mask[root[[0, 2]]] = 0.0
    guide = Guide(reference=_full(model, reference, frames), keep=mask)
    return Plan(guide, frames, reference.start, reference=reference)


def plan_control(model: MotionModel, reference: Reference, joints: str | None = None, subtree: str | None = None,
                 trajectory: bool = False, frames: int | None = None) -> Plan:
    """Keep a joint set (and/or the root path) of the reference for every frame."""
    names = joint_names(model.codec, joints, subtree)
    lower = joints == "lower-body"
    channels = [feature_channels(model.codec, names, with_root=lower)] if names else []
    if trajectory:
        own_skeleton = np.abs(reference.features).sum(axis=0)[model.codec.layout.indices(("rotation",))].any()
        channels.append(trajectory_channels(model.codec, with_heading=bool(own_skeleton)))
    if not channels:
        raise OptionError("joints", "nothing to keep: give joints, subtree or trajectory")
    length = frames or reference.frames
    if length > reference.frames:
        raise SinMDMError(f"the reference has only {reference.frames} frames; asked for {length}")
    mask = np.zeros((model.features, length))
    mask[np.unique(np.concatenate(channels))] = 1.0
    return Plan(Guide(reference=_full(model, reference, length), keep=mask), length, reference.start, reference=reference)


def parse_frame_range(text: str) -> tuple[int, int]:
    """'START:STOP' as a frame range."""
    try:
        start, stop = (int(v) for v in text.split(":"))
    except ValueError:
        raise OptionError("frame_range", f"takes START:STOP (frames), got '{text}'") from None
    return start, stop


def _check_frame_range(frame_range: tuple[int, int], frames: int) -> None:
    start, stop = frame_range
    if start >= stop:
        raise OptionError("frame_range", f"start must be before stop, got {start}:{stop}")
    if start < 0 or stop > frames:
        raise OptionError("frame_range", f"{start}:{stop} is outside the reference (0..{frames})")


def check_harmonize(model: MotionModel, reference: Reference, factor: int = 2, frame_range: tuple[int, int] | None = None,
                    joints: str | None = None, border: int = HARMONIZE_BORDER) -> None:
    """Every option of a harmonization, checked before any sampling."""
    check_whole("factor", factor, 1)
    check_whole("border", border)
    if frame_range is not None:
        _check_frame_range(frame_range, reference.frames)
    if joints:
        joint_names(model.codec, joints)


def plan_harmonize(model: MotionModel, reference: Reference, factor: int = 2, frame_range: tuple[int, int] | None = None,
                   joints: str | None = None, base: np.ndarray | None = None, border: int = HARMONIZE_BORDER) -> Plan:
    """Whole clip: ILVR towards the reference's low frequencies (style transfer).
    Partial (frames and/or joints): the reference's portion is pasted into `base`
    (a generated motion (frames, F), or one per sample (count, frames, F)) and only that
    portion and its borders are harmonized; the rest of `base` is kept."""
    check_harmonize(model, reference, factor, frame_range, joints, border)
    frames = reference.frames
    target = _full(model, reference, frames)
    if frame_range is None and not joints:
        region = np.ones((model.features, frames))
        return Plan(Guide(reference=target, harmonize=region, factor=factor), frames, reference.start, reference=reference)
    if base is None:
        raise SinMDMError("partial harmonization needs a base motion")
    start, stop = frame_range or (0, frames)
    channels = feature_channels(model.codec, joint_names(model.codec, joints), with_root=False) if joints else np.arange(model.features)
    pasted = np.zeros((model.features, frames))
    pasted[np.ix_(channels, np.arange(start, stop))] = 1.0
    composite = np.swapaxes(base, -1, -2) * (1 - pasted) + target * pasted
    # The harmonized region grows by `border` frames on each side with a linear fade.
    soft = frame_ramp(frames + 2 * border, [(start, stop + 2 * border)], border)[border:-border] if border else pasted[0]
    region = np.zeros((model.features, frames))
    region[channels] = np.maximum(soft, 0.0)
    keep = 1.0 - region
    return Plan(Guide(reference=composite, keep=keep, harmonize=region, factor=factor), frames, reference.start, reference=reference)


def harmonize(model: MotionModel, reference: Reference, options: SamplingOptions = SamplingOptions(), factor: int = 2,
              frame_range: tuple[int, int] | None = None, joints: str | None = None, border: int = HARMONIZE_BORDER,
              progress: Callable[[int, int], None] | None = None, force: bool = False) -> GenerationResult:
    """Harmonize the whole reference, or (frame_range and/or joints) its portion pasted into
    a generated base motion: sample i's base uses seed + i, so each sample reproduces alone."""
    check_harmonize(model, reference, factor, frame_range, joints, border)
    base = None
    if frame_range is not None or joints:
        check_length(reference.frames, model.codec.fps, force)
        base = sample_features(model, reference.frames, options)
    plan = plan_harmonize(model, reference, factor, frame_range, joints, base, border)
    return run_plan(model, plan, options, progress, force)


def land_on_reference(model: MotionModel, plan: Plan, features: np.ndarray) -> np.ndarray:
    """After in-betweening, spread the root's x/z drift over the generated gap of the
    sampled (count, frames, F) features so the kept end lands where it stands in the reference."""
    if plan.fix_root is None or plan.reference is None:
        return features
    root = model.codec.layout.indices(("root",))
    if not len(root):
        return features
    gap_start, gap_stop = plan.fix_root
    dx, dz = root[0], root[2]
    features = features.copy()
    ref = plan.reference.features
    for sample in features:
        for channel in (dx, dz):
            want = ref[gap_start + 1 : gap_stop + 1, channel].sum()
            got = sample[gap_start + 1 : gap_stop + 1, channel].sum()
            sample[gap_start + 1 : gap_stop + 1, channel] += (want - got) / (gap_stop - gap_start)
    return features


def run_plan(model: MotionModel, plan: Plan, options: SamplingOptions = SamplingOptions(),
             progress: Callable[[int, int], None] | None = None, force: bool = False) -> GenerationResult:
    """Sample a plan (its length capped as `check_length` unless `force`)."""
    check_length(plan.frames, model.codec.fps, force)
    return generate(model, plan.frames, options, guide=plan.guide, start=plan.start, progress=progress,
                    adjust=lambda features: land_on_reference(model, plan, features))
