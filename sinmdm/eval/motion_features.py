"""Metric features from BVH files, so that any system's output is scored the same way.

Per frame at 30 fps (reference notes, section 6): the 6D local rotation (first
two rows of the rotation matrix) of each protocol joint, then one contact label
per contact joint; root translation channels are left out. An `EvalProtocol`
is derived once from the REFERENCE clip and applied unchanged to every sample;
joints are found by name in each file, so a peer's output on the same joint
names is scored even when its skeleton has extra or fewer other joints.

Presets:
- ``default``: every joint with rotation channels, contact joints detected
  automatically (`build_codec`), the codec's contact speed, slerp to 30 fps.
- ``mixamo24``: the paper's protocol (GANimator's ``bvh_parser`` and
  ``skeleton_database``): 24 Mixamo joints, each the first joint in file order
  whose name without its namespace (``mixamorig7:``) contains the pattern;
  contacts on the four toe joints below 0.018 per frame; 30 fps by dropping
  frames. Units follow that code exactly, per file: numbers are divided by 100
  when the Hips OFFSET y exceeds 10, else taken as they are, and the 0.018
  threshold applies in those units (the project's own unit detection is used
  by ``default`` only).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..runtime.animation import Animation, animation_from_bvh, global_positions
from ..runtime.bvh import BVH, Skeleton, read_bvh
from ..runtime.contacts import contact_labels
from ..runtime.errors import SinMDMError
from ..runtime.features import build_codec, resample_animation, skeleton_size, unit_scale
from ..runtime.rotations import matrix_to_6d
from . import metrics

__all__ = [
    "EVAL_FPS",
    "PRESETS",
    "MIXAMO24_JOINTS",
    "MIXAMO24_CONTACT_JOINTS",
    "EvalProtocol",
    "protocol_for",
    "resolve_joints",
    "eval_features",
    "evaluate_files",
]

EVAL_FPS = 30.0
PRESETS = ("default", "mixamo24")

MIXAMO24_JOINTS = (
    "Hips",
    "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase", "LeftToe_End",
    "RightUpLeg", "RightLeg", "RightFoot", "RightToeBase", "RightToe_End",
    "Spine", "Spine1", "Spine2", "Neck", "Head",
    "LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand",
    "RightShoulder", "RightArm", "RightForeArm", "RightHand",
)  # fmt: skip
# GANimator's order; the order of feature columns does not change any distance.
MIXAMO24_CONTACT_JOINTS = ("LeftToe_End", "RightToe_End", "LeftToeBase", "RightToeBase")
MIXAMO24_CONTACT_THRESHOLD = 0.018  # metres per frame at 30 fps

# Beyond this ratio of character sizes, a sample is taken to be in other units
# than the reference (GANimator writes metres for a reference in cm).
UNITS_MISMATCH_RATIO = 4.0


@dataclass(frozen=True)
class EvalProtocol:
    preset: str
    joints: tuple[str, ...]  # names (match "exact") or name patterns (match "contains")
    contact_joints: tuple[str, ...]
    contact_threshold: float  # metres per frame at `fps`
    resample: str  # "drop" (integer ratios) or "slerp"
    scale: float  # metres per file unit of the reference
    character_size: float  # metres, the reference's rest-pose extent
    units: str | float = "auto"
    match: str = "exact"  # or "contains": first joint whose namespace-free name contains the pattern
    fps: float = EVAL_FPS

    @property
    def width(self) -> int:
        return 6 * len(self.joints) + len(self.contact_joints)


# --------------------------------------------------------------------------- joints


def _without_namespace(name: str) -> str:
    # GANimator cuts at the first ':' ("mixamorig7:Hips" -> "Hips").
    return name.split(":", 1)[1] if ":" in name else name


def _find_joint(names: Sequence[str], wanted: str, match: str) -> int | None:
    if match == "exact":
        return names.index(wanted) if wanted in names else None
    return next((j for j, name in enumerate(names) if wanted in _without_namespace(name)), None)


def resolve_joints(skeleton: Skeleton, wanted: Sequence[str], match: str = "exact", where: str = "motion") -> list[int]:
    """Joint indices of `wanted` in the skeleton; a SinMDMError names `where` and the missing joints."""
    found = [_find_joint(skeleton.names, name, match) for name in wanted]
    missing = [name for name, index in zip(wanted, found) if index is None]
    if missing:
        shown = ", ".join(repr(name) for name in missing[:4]) + (f" and {len(missing) - 4} more" if len(missing) > 4 else "")
        kind = "joint named" if match == "exact" else "joint matching"
        raise SinMDMError(
            f"{where}: no {kind} {shown} (needed by the evaluation protocol; is it on another skeleton?)"
        )
    return [int(index) for index in found]  # type: ignore[arg-type]


# --------------------------------------------------------------------------- protocol


def protocol_for(
    reference: BVH, preset: str = "default", source_fps: float | None = None, units: str | float = "auto"
) -> EvalProtocol:
    """The evaluation protocol for samples of `reference` (see the module docstring)."""
    where = _where(reference)
    if preset == "default":
        codec = build_codec(reference, fps=EVAL_FPS, units=units, source_fps=_check_fps(source_fps), resample="slerp")
        names = reference.skeleton.names
        if not codec.rotation_joints:
            raise SinMDMError(f"{where}: no joint has rotation channels, nothing to evaluate")
        return EvalProtocol(
            preset=preset,
            joints=tuple(names[j] for j in codec.rotation_joints),
            contact_joints=tuple(names[j] for j in codec.contact_joints),
            contact_threshold=codec.contact_speed / EVAL_FPS,
            resample="slerp",
            scale=codec.scale,
            character_size=codec.size,
            units=units,
        )
    if preset == "mixamo24":
        skeleton = reference.skeleton
        resolve_joints(skeleton, MIXAMO24_JOINTS, "contains", f"{where} (mixamo24 preset)")
        scale = unit_scale(skeleton, units) if units != "auto" else paper_scale(skeleton)
        return EvalProtocol(
            preset=preset,
            joints=MIXAMO24_JOINTS,
            contact_joints=MIXAMO24_CONTACT_JOINTS,
            contact_threshold=MIXAMO24_CONTACT_THRESHOLD,
            resample="drop",
            scale=scale,
            character_size=skeleton_size(skeleton) * scale,
            units=units,
            match="contains",
        )
    raise SinMDMError(f"unknown evaluation preset {preset!r}: use {' or '.join(PRESETS)}")


# --------------------------------------------------------------------------- features


def _where(bvh: BVH) -> str:
    return os.path.basename(bvh.path) if bvh.path else "motion"


def _check_fps(source_fps: float | None) -> float | None:
    if source_fps is not None and not (np.isfinite(source_fps) and source_fps > 0):
        raise SinMDMError(f"source frame rate must be a number > 0, got {source_fps}")
    return source_fps


def paper_scale(skeleton: Skeleton) -> float:
    """GANimator's `bvh_parser` rule, per file: scale by 1/100 when the OFFSET y of the
    first protocol joint (Hips) exceeds 10, else keep the file's numbers as metres."""
    hips = resolve_joints(skeleton, MIXAMO24_JOINTS[:1], "contains", "mixamo24 preset")[0]
    return 0.01 if skeleton.offsets[hips, 1] > 10 else 1.0


def _file_scale(skeleton: Skeleton, protocol: EvalProtocol) -> float:
    """Metres per unit: the reference's, unless units are automatic and this
    file's character is clearly in other units (its size off by > 4x)."""
    if protocol.units != "auto":
        return protocol.scale
    if protocol.preset == "mixamo24":
        return paper_scale(skeleton)
    ratio = skeleton_size(skeleton) * protocol.scale / protocol.character_size
    if 1 / UNITS_MISMATCH_RATIO <= ratio <= UNITS_MISMATCH_RATIO:
        return protocol.scale
    return unit_scale(skeleton, "auto")


def _animation_at(bvh: BVH, protocol: EvalProtocol, source_fps: float | None) -> Animation:
    animation = animation_from_bvh(bvh)
    if _check_fps(source_fps) is not None:
        animation = Animation(animation.skeleton, animation.rotations, animation.translations, float(source_fps))
    try:
        return resample_animation(animation, protocol.fps, protocol.resample)
    except SinMDMError as exc:
        raise SinMDMError(f"{_where(bvh)}: {exc}") from None


def eval_features(bvh: BVH, protocol: EvalProtocol, source_fps: float | None = None) -> np.ndarray:
    """(T, 6 * joints + contacts) float64 features at the protocol's frame rate."""
    where = _where(bvh)
    joints = resolve_joints(bvh.skeleton, protocol.joints, protocol.match, where)
    contacts = resolve_joints(bvh.skeleton, protocol.contact_joints, protocol.match, where)
    animation = _animation_at(bvh, protocol, source_fps)
    frames = animation.frames
    rotations = matrix_to_6d(animation.rotations[:, joints]).reshape(frames, -1)
    if not contacts:
        return rotations
    metres = global_positions(animation)[:, contacts] * _file_scale(bvh.skeleton, protocol)
    # fps=1: the threshold is a displacement per frame, not a speed.
    labels = contact_labels(metres, 1.0, protocol.contact_threshold).astype(np.float64)
    return np.concatenate([rotations, labels], axis=1)


def _minimum_frames() -> tuple[int, int]:
    """(reference, sample) lengths the five metrics need."""
    reference = max(metrics.COVERAGE_WINDOW + 1, metrics.MIN_SEGMENT, metrics.LOCAL_WINDOW, metrics.INTRA_WINDOW + 2)
    sample = max(metrics.COVERAGE_WINDOW, metrics.MIN_SEGMENT, metrics.LOCAL_WINDOW + 1, metrics.INTRA_WINDOW + 1)
    return reference, sample


def _check_length(where: str, frames: int, needed: int, fps: float) -> None:
    if frames < needed:
        raise SinMDMError(f"{where} has {frames} frames at {fps:g} fps; the metrics need at least {needed}")


def evaluate_files(
    reference_path: str | os.PathLike,
    sample_paths: Sequence[str | os.PathLike],
    preset: str = "default",
    seed: int = 0,
    source_fps: float | None = None,
) -> dict:
    """Score BVH samples against their reference: the five metrics plus what was compared.

    `source_fps` overrides the declared frame rate of every file.
    """
    if preset not in PRESETS:
        raise SinMDMError(f"unknown evaluation preset {preset!r}: use {' or '.join(PRESETS)}")
    if not sample_paths:
        raise SinMDMError("no samples to evaluate: give at least one generated BVH file")
    reference = read_bvh(reference_path)
    protocol = protocol_for(reference, preset, source_fps)
    reference_features = eval_features(reference, protocol, source_fps)
    samples = [read_bvh(path) for path in sample_paths]
    sample_features = [eval_features(sample, protocol, source_fps) for sample in samples]

    reference_minimum, sample_minimum = _minimum_frames()
    _check_length(f"reference {_where(reference)}", len(reference_features), reference_minimum, protocol.fps)
    for path, features in zip(sample_paths, sample_features):
        _check_length(f"sample {os.path.basename(path)}", len(features), sample_minimum, protocol.fps)
    try:
        scores = metrics.evaluate(reference_features, sample_features, seed=seed)
    except ValueError as exc:
        raise SinMDMError(f"cannot evaluate: {exc}") from None
    names = reference.skeleton.names
    return {
        **scores,
        "samples": len(sample_features),
        "reference_frames": len(reference_features),
        "sample_frames": [len(features) for features in sample_features],
        "preset": preset,
        "feature_width": protocol.width,
        "fps": protocol.fps,
        "joints": [names[j] for j in resolve_joints(reference.skeleton, protocol.joints, protocol.match)],
        "contact_joints": [names[j] for j in resolve_joints(reference.skeleton, protocol.contact_joints, protocol.match)],
        "contact_threshold": protocol.contact_threshold,
        "plausibility": _plausibility(reference, samples, source_fps),
    }


def _plausibility(reference: BVH, samples: list[BVH], source_fps: float | None) -> dict:
    from .plausibility import plausibility

    if source_fps is not None:
        reference, *samples = [BVH(b.skeleton, 1.0 / source_fps, b.values, b.path) for b in [reference, *samples]]
    return plausibility(reference, samples)
