"""Motion features: the representation the model is trained on and samples.

Per frame, in channel order (reference notes, section 4, generalised to any skeleton):
  1. a 6D rotation (first two rows of the local rotation matrix) for every joint
     with rotation channels;
  2. the local translation (metres) of every other joint whose position
     channels vary over the clip;
  3. one contact label per contact joint;
  4. the trajectory joint (the joint that carries the character, see rig.py) as
     (d<h1>, <up>, d<h2>): velocity per frame along the two horizontal axes of its
     parent's frame, height absolute ("dx, y, dz" for a Y-up clip); the start
     position is kept aside. Static joints above it are not features: their pose
     is stored and written back exactly.

A `MotionCodec` is everything needed to go both ways for one skeleton: it is
built once from the training clip and stored in checkpoints and ONNX metadata.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .animation import Animation, animation_from_bvh, chunks_to_bvh, global_positions
from .bvh import BVH, MAX_FRAME_TIME, MAX_JOINT_FRAMES, MIN_FRAME_TIME, Skeleton
from .contacts import contact_labels, default_contact_speed, detect_contact_joints, resting_heights
from .errors import OptionError, SinMDMError
from .options import check_number
from .resample import resample_count, resample_linear, resample_rotations
from .rig import AXIS_NAMES, analyse_rig, skeleton_extent as skeleton_size
from .rotations import by_frame_chunks, matrix_to_6d, matrix_to_quat, quat_to_matrix, sixd_to_matrix

ROT6D = ("r00", "r01", "r02", "r10", "r11", "r12")
UNIT_SCALES = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254, "ft": 0.3048}
MIN_SCALE, MAX_SCALE = 1e-6, 1e6  # metres per file unit
MAX_METRES = 1e6  # no position of a character clip lies 1,000 km from the origin
MAX_CLIP_SECONDS = 3600  # the longest clip, after resampling to the feature rate


@dataclass(frozen=True)
class FeatureBlock:
    kind: str  # "rotation" | "translation" | "contact" | "root"
    joint: str
    start: int
    stop: int
    components: tuple[str, ...]


@dataclass(frozen=True)
class FeatureLayout:
    """Which feature channels belong to which joint and component, by name."""

    blocks: tuple[FeatureBlock, ...]

    @property
    def width(self) -> int:
        return self.blocks[-1].stop if self.blocks else 0

    def indices(self, kinds: tuple[str, ...] | None = None, joints: set[str] | None = None) -> np.ndarray:
        """Channel indices of the blocks of the given kinds and/or joints."""
        selected = [
            np.arange(b.start, b.stop)
            for b in self.blocks
            if (kinds is None or b.kind in kinds) and (joints is None or b.joint in joints)
        ]
        return np.concatenate(selected) if selected else np.zeros(0, dtype=np.int64)

    def joints(self, kind: str) -> list[str]:
        return [b.joint for b in self.blocks if b.kind == kind]

    def to_dict(self) -> list[dict]:
        return [
            {"kind": b.kind, "joint": b.joint, "start": b.start, "stop": b.stop, "components": list(b.components)}
            for b in self.blocks
        ]

    @classmethod
    def from_dict(cls, blocks: list[dict]) -> "FeatureLayout":
        return cls(tuple(FeatureBlock(b["kind"], b["joint"], b["start"], b["stop"], tuple(b["components"])) for b in blocks))


def skeleton_to_dict(skeleton: Skeleton) -> dict:
    return {
        "names": list(skeleton.names),
        "parents": [int(p) for p in skeleton.parents],
        "offsets": np.asarray(skeleton.offsets, dtype=float).tolist(),
        "channels": [list(c) for c in skeleton.channels],
        "end_sites": [[int(p), None if o is None else np.asarray(o, dtype=float).tolist()] for p, o in skeleton.end_sites],
    }


def skeleton_from_dict(data: dict) -> Skeleton:
    return Skeleton(
        names=tuple(data["names"]),
        parents=np.asarray(data["parents"], dtype=np.int64),
        offsets=np.asarray(data["offsets"], dtype=np.float64).reshape(-1, 3),
        channels=tuple(tuple(c) for c in data["channels"]),
        end_sites=tuple((int(p), None if o is None else np.asarray(o, dtype=np.float64)) for p, o in data["end_sites"]),
    )


def unit_scale(skeleton: Skeleton, units: str | float = "auto") -> float:
    """Metres per file unit. 'auto' guesses from the rest-pose size: characters
    are taken to be between a few centimetres and ~20 m tall."""
    if isinstance(units, (int, float)):
        return _checked_scale(float(units))
    if units in UNIT_SCALES:
        return UNIT_SCALES[units]
    if units != "auto":
        try:
            return _checked_scale(float(units))
        except ValueError:
            raise OptionError("units", f"unknown units '{units}': use auto, m, cm, mm, in, ft or metres per unit") from None
    size = skeleton_size(skeleton)
    if size > 300:
        return 0.001
    if size > 20:
        return 0.01
    return 1.0


def _checked_scale(scale: float) -> float:
    return check_number("units", scale, MIN_SCALE, MAX_SCALE)


def check_source_fps(source_fps: float) -> float:
    """A frame rate inside the range the BVH reader accepts for a file's own frame time."""
    return check_number("source_fps", source_fps, 1 / MAX_FRAME_TIME, 1 / MIN_FRAME_TIME)


def _check_resampled_length(animation: Animation, fps: float, name: str) -> None:
    """Refuse, before any work, a clip that resampling would turn into more than an
    hour of frames: its frame rate is most likely wrong."""
    count, joints = resample_count(animation.frames, animation.fps, fps), animation.skeleton.num_joints
    if count > MAX_CLIP_SECONDS * fps + 1 or count * joints > MAX_JOINT_FRAMES:
        raise OptionError(
            "source_fps",
            f"{name} at {animation.fps:g} fps would be {count:,} frames of {joints} joints at {fps:g} fps "
            f"({count / fps / 3600:.1f} hours), over the limit of {MAX_CLIP_SECONDS // 3600} hour and "
            f"{MAX_JOINT_FRAMES:,} joint-frames: if its frame rate is wrong, give the real one",
        )


def clip_name(clip: BVH | Animation) -> str:
    return clip.path if isinstance(clip, BVH) and clip.path else "the clip"


def resample_animation(animation: Animation, fps: float, method: str = "slerp", name: str = "the clip") -> Animation:
    """Change the frame rate: slerp rotations and interpolate translations, or
    ('drop') keep every k-th frame as the reference code did (integer ratios only)."""
    if abs(animation.fps - fps) < 1e-6 * fps:
        return animation
    _check_resampled_length(animation, fps, name)
    if method == "drop":
        step = animation.fps / fps
        if abs(step - round(step)) > 1e-3 or round(step) < 1:
            raise SinMDMError(f"cannot drop frames from {animation.fps:g} to {fps:g} fps: not an integer ratio")
        k = int(round(step))
        return Animation(animation.skeleton, animation.rotations[::k], animation.translations[::k], fps)
    return Animation(
        animation.skeleton,
        resample_rotations(animation.rotations, animation.fps, fps),
        resample_linear(animation.translations, animation.fps, fps),
        fps,
    )


def clip_animation(clip: BVH | Animation, fps: float, method: str, source_fps: float | None = None,
                   skeleton: Skeleton | None = None) -> Animation:
    """A clip with at least one frame as an animation at `fps` (from `source_fps`, its real
    rate, when given), checked against `skeleton` when given; errors name the clip."""
    name = clip_name(clip)
    if clip.frames == 0:
        raise SinMDMError(f"{name} has no frames: a clip needs at least one frame of motion")
    animation = animation_from_bvh(clip) if isinstance(clip, BVH) else clip
    if skeleton is not None:
        check_same_skeleton(skeleton, animation.skeleton)
    if source_fps is not None:
        animation = Animation(animation.skeleton, animation.rotations, animation.translations, check_source_fps(source_fps))
    return resample_animation(animation, fps, method, name)


def _check_metres(values: np.ndarray, name: str, scale: float) -> None:
    if not np.all(np.abs(values) <= MAX_METRES):  # also refuses NaN
        raise SinMDMError(
            f"{name} has positions beyond {MAX_METRES:g} m at {scale:g} metres per unit: its units or values are wrong"
        )


def check_same_skeleton(expected: Skeleton, got: Skeleton, what: str = "clip") -> None:
    if expected.names == got.names and np.array_equal(expected.parents, got.parents):
        return
    if len(expected.names) != len(got.names):
        raise SinMDMError(
            f"{what} has {len(got.names)} joints but the model's skeleton has {len(expected.names)}"
        )
    for j, (a, b) in enumerate(zip(expected.names, got.names)):
        if a != b:
            raise SinMDMError(f"{what} skeleton differs from the model's: joint {j} is '{b}', expected '{a}'")
    j = int(np.flatnonzero(expected.parents != got.parents)[0])
    raise SinMDMError(f"{what} skeleton differs from the model's: joint '{expected.names[j]}' has another parent")


@dataclass(frozen=True)
class MotionCodec:
    skeleton: Skeleton
    fps: float  # feature frame rate
    scale: float  # metres per file unit
    trajectory_joint: int | None
    translation_joints: tuple[int, ...]
    contact_joints: tuple[int, ...]
    contact_speed: float  # metres per second
    rest_translations: np.ndarray  # (J, 3) file units, used for translations that are not features
    resample: str = "slerp"
    up_axis: int = 1  # world axis index (1 = Y-up, 2 = Z-up)
    height_axis: int = 1  # the trajectory joint's parent-frame axis that points up
    fixed_joints: tuple[int, ...] = ()  # static joints above the trajectory joint
    rest_rotations: np.ndarray | None = None  # (J, 3, 3) used for rotations that are not features (quaternions on disk)
    # metres, world height: each contact joint's resting height in the clip (contacts.resting_heights);
    # the cleanup lifts a pin below it. None for models exported before it was measured.
    contact_floors: tuple[float, ...] | None = None
    layout: FeatureLayout = field(init=False, compare=False)

    def __post_init__(self) -> None:
        joints = self.skeleton.num_joints
        if np.shape(self.rest_translations) != (joints, 3):
            raise ValueError(f"rest translations have shape {np.shape(self.rest_translations)}, expected ({joints}, 3)")
        if self.rest_rotations is not None and np.shape(self.rest_rotations) != (joints, 3, 3):
            raise ValueError(f"rest rotations have shape {np.shape(self.rest_rotations)}, expected ({joints}, 3, 3)")
        if self.contact_floors is not None and len(self.contact_floors) != len(self.contact_joints):
            raise ValueError(f"{len(self.contact_floors)} contact floors for {len(self.contact_joints)} contact joints")
        object.__setattr__(self, "layout", self._make_layout())

    def _make_layout(self) -> FeatureLayout:
        blocks, start = [], 0
        names = self.skeleton.names

        def add(kind: str, joint: str, components: tuple[str, ...]) -> None:
            nonlocal start
            blocks.append(FeatureBlock(kind, joint, start, start + len(components), components))
            start += len(components)

        for j in self.rotation_joints:
            add("rotation", names[j], ROT6D)
        for j in self.translation_joints:
            add("translation", names[j], ("x", "y", "z"))
        for j in self.contact_joints:
            add("contact", names[j], ("contact",))
        if self.trajectory_joint is not None:
            h1, h2 = self.horizontal_axes
            add("root", names[self.trajectory_joint], (f"d{AXIS_NAMES[h1]}", AXIS_NAMES[self.height_axis], f"d{AXIS_NAMES[h2]}"))
        return FeatureLayout(tuple(blocks))

    @property
    def horizontal_axes(self) -> tuple[int, int]:
        """The trajectory's two horizontal axes in its parent's frame (x, z when Y-up)."""
        h1, h2 = (a for a in range(3) if a != self.height_axis)
        return h1, h2

    @property
    def handedness(self) -> float:
        """+1 when (first horizontal, up, second horizontal) is right-handed (x, y, z for
        Y-up), -1 otherwise (x, z, y for Z-up): paths move between layouts with it."""
        h1, h2 = self.horizontal_axes
        return float(np.cross(np.eye(3)[h1], np.eye(3)[self.height_axis])[h2])

    @property
    def rotation_joints(self) -> list[int]:
        fixed = set(self.fixed_joints)
        return [j for j in range(self.skeleton.num_joints) if self.skeleton.rotation_order(j) and j not in fixed]

    @property
    def width(self) -> int:
        return self.layout.width

    @property
    def size(self) -> float:
        """Character size in metres."""
        return skeleton_size(self.skeleton) * self.scale

    # ------------------------------------------------------------------ encode
    def animation(self, clip: BVH | Animation, source_fps: float | None = None) -> Animation:
        """The clip as an animation on this codec's skeleton, at the codec's frame rate."""
        return clip_animation(clip, self.fps, self.resample, source_fps, self.skeleton)

    def encode(self, clip: BVH | Animation, source_fps: float | None = None) -> np.ndarray:
        """(T, F) float32 features at the codec's frame rate."""
        animation = self.animation(clip, source_fps)
        _check_metres(animation.translations * self.scale, clip_name(clip), self.scale)
        parts = []
        matrices = animation.rotations[:, self.rotation_joints]
        parts.append(matrix_to_6d(matrices).reshape(animation.frames, -1))
        metres = animation.translations * self.scale
        parts.append(metres[:, list(self.translation_joints)].reshape(animation.frames, -1))
        if self.contact_joints:
            positions = global_positions(animation)[:, list(self.contact_joints)] * self.scale
            parts.append(contact_labels(positions, self.fps, self.contact_speed))
        if self.trajectory_joint is not None:
            root = metres[:, self.trajectory_joint]
            velocity = np.diff(root[:, list(self.horizontal_axes)], axis=0)
            velocity = np.concatenate([velocity[:1] if len(velocity) else np.zeros((1, 2)), velocity], axis=0)
            parts.append(np.stack([velocity[:, 0], root[:, self.height_axis], velocity[:, 1]], axis=1))
        return np.concatenate(parts, axis=1).astype(np.float32)

    def start_position(self, clip: BVH | Animation, source_fps: float | None = None) -> np.ndarray:
        """The trajectory joint's horizontal position at the first frame, in metres."""
        if self.trajectory_joint is None:
            return np.zeros(2)
        animation = self.animation(clip, source_fps)
        return animation.translations[0, self.trajectory_joint, list(self.horizontal_axes)] * self.scale

    # ------------------------------------------------------------------ decode
    def _checked(self, features: np.ndarray) -> np.ndarray:
        features = np.asarray(features)
        if features.ndim != 2 or features.shape[1] != self.width:
            raise SinMDMError(f"features have shape {features.shape}, expected (frames, {self.width})")
        return features

    def local_rotations(self, features: np.ndarray) -> np.ndarray:
        """(T, J, 3, 3) local rotations of (T, F) features (rest rotations where not features)."""
        rest = np.eye(3) if self.rest_rotations is None else self.rest_rotations
        matrices = np.broadcast_to(rest, (len(features), self.skeleton.num_joints, 3, 3)).copy()
        rot = self.layout.indices(("rotation",))
        matrices[:, self.rotation_joints] = sixd_to_matrix(features[:, rot].reshape(len(features), -1, 6))
        return matrices

    def local_translations(self, features: np.ndarray, path: np.ndarray | None) -> np.ndarray:
        """(T, J, 3) local translations, file units, of (T, F) features and the trajectory
        joint's (T, 3) `path` in metres (`root_path`)."""
        frames = len(features)
        translations = np.broadcast_to(self.rest_translations, (frames, self.skeleton.num_joints, 3)).copy()
        if self.translation_joints:
            metres = features[:, self.layout.indices(("translation",))].astype(np.float64).reshape(frames, -1, 3)
            translations[:, list(self.translation_joints)] = metres / self.scale
        if path is not None:
            translations[:, self.trajectory_joint] = path / self.scale
        return translations

    def root_path(self, features: np.ndarray, start: np.ndarray | None = None) -> np.ndarray | None:
        """(T, 3) metres: the trajectory joint's path, integrated from `start` (horizontal,
        default the origin) over the velocities of frames 1..T-1; None without one."""
        if self.trajectory_joint is None:
            return None
        dx, y, dz = features[:, self.layout.indices(("root",))].astype(np.float64).T
        origin = np.zeros(2) if start is None else np.asarray(start, dtype=np.float64)
        h1, h2 = self.horizontal_axes
        path = np.zeros((len(features), 3))
        path[:, h1] = origin[0] + np.concatenate([[0.0], np.cumsum(dx[1:])])
        path[:, self.height_axis] = y
        path[:, h2] = origin[1] + np.concatenate([[0.0], np.cumsum(dz[1:])])
        return path

    def decode(self, features: np.ndarray, start: np.ndarray | None = None) -> Animation:
        """Animation at the codec's frame rate from (T, F) features; the root path is
        re-integrated from `start` (horizontal, metres, default the origin)."""
        features = self._checked(features)
        matrices = by_frame_chunks(self.local_rotations, features)
        translations = self.local_translations(features, self.root_path(features, start))
        return Animation(self.skeleton, matrices, translations, self.fps)

    def decode_bvh(self, features: np.ndarray, start: np.ndarray | None = None,
                   replaced: Animation | None = None) -> BVH:
        """`animation_to_bvh(decode(features, start))` a chunk of frames at a time: a long
        motion is never held whole as matrices. `replaced`: an animation of some joints
        (a skeleton whose joint names are this one's) whose rotations and translations
        take the place of the decoded ones (the contact cleanup's legs)."""
        features = self._checked(features)
        path = self.root_path(features, start)
        names = self.skeleton.names
        joints = [] if replaced is None else [names.index(n) for n in replaced.skeleton.names]

        def chunk_at(a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
            rotations = self.local_rotations(features[a:b])
            translations = self.local_translations(features[a:b], None if path is None else path[a:b])
            if joints:
                rotations[:, joints] = replaced.rotations[a:b]
                translations[:, joints] = replaced.translations[a:b]
            return rotations, translations

        return chunks_to_bvh(self.skeleton, self.fps, len(features), chunk_at)

    def restricted(self, joints: list[int]) -> tuple["MotionCodec", np.ndarray]:
        """This codec on the sub-skeleton of `joints` (each with its parent, in file order)
        and the indices of this codec's feature channels that make its features."""
        at = {j: i for i, j in enumerate(joints)}
        skeleton = self.skeleton
        sub = Skeleton(
            tuple(skeleton.names[j] for j in joints),
            np.array([at[skeleton.parents[j]] if skeleton.parents[j] >= 0 else -1 for j in joints]),
            skeleton.offsets[joints],
            tuple(skeleton.channels[j] for j in joints),
            tuple((at[p], o) for p, o in skeleton.end_sites if p in at),
        )
        codec = MotionCodec(
            sub, self.fps, self.scale, None if self.trajectory_joint is None else at[self.trajectory_joint],
            tuple(at[j] for j in self.translation_joints if j in at), tuple(at[j] for j in self.contact_joints if j in at),
            self.contact_speed, np.asarray(self.rest_translations)[joints], self.resample, self.up_axis,
            self.height_axis, tuple(at[j] for j in self.fixed_joints if j in at),
            None if self.rest_rotations is None else np.asarray(self.rest_rotations)[joints],
            None if self.contact_floors is None else tuple(f for j, f in zip(self.contact_joints, self.contact_floors) if j in at),
        )
        blocks = {(b.kind, b.joint): b for b in self.layout.blocks}
        channels = [np.arange(blocks[b.kind, b.joint].start, blocks[b.kind, b.joint].stop) for b in codec.layout.blocks]
        return codec, np.concatenate(channels) if channels else np.zeros(0, dtype=np.int64)

    # ----------------------------------------------------------- serialise
    def to_dict(self) -> dict:
        names = self.skeleton.names
        return {
            "skeleton": skeleton_to_dict(self.skeleton),
            "fps": self.fps,
            "scale": self.scale,
            "trajectory_joint": None if self.trajectory_joint is None else names[self.trajectory_joint],
            "translation_joints": [names[j] for j in self.translation_joints],
            "contact_joints": [names[j] for j in self.contact_joints],
            "contact_speed": self.contact_speed,
            "rest_translations": np.asarray(self.rest_translations).tolist(),
            "resample": self.resample,
            "up_axis": self.up_axis,
            "height_axis": self.height_axis,
            "fixed_joints": [names[j] for j in self.fixed_joints],
            "rest_rotations": None if self.rest_rotations is None else matrix_to_quat(self.rest_rotations).tolist(),
            **({} if self.contact_floors is None else {"contact_floors": list(self.contact_floors)}),
            "layout": self.layout.to_dict(),
        }

    @classmethod
    def from_dict(cls, data: dict) -> "MotionCodec":
        skeleton = skeleton_from_dict(data["skeleton"])
        index = {n: i for i, n in enumerate(skeleton.names)}
        codec = cls(
            skeleton=skeleton,
            fps=float(data["fps"]),
            scale=float(data["scale"]),
            trajectory_joint=None if data["trajectory_joint"] is None else index[data["trajectory_joint"]],
            translation_joints=tuple(index[n] for n in data["translation_joints"]),
            contact_joints=tuple(index[n] for n in data["contact_joints"]),
            contact_speed=float(data["contact_speed"]),
            rest_translations=np.asarray(data["rest_translations"], dtype=np.float64),
            resample=data.get("resample", "slerp"),
            up_axis=int(data.get("up_axis", 1)),
            height_axis=int(data.get("height_axis", 1)),
            fixed_joints=tuple(index[n] for n in data.get("fixed_joints", [])),
            rest_rotations=None if data.get("rest_rotations") is None else quat_to_matrix(np.asarray(data["rest_rotations"], dtype=np.float64)),
            contact_floors=None if data.get("contact_floors") is None else tuple(float(f) for f in data["contact_floors"]),
        )
        if "layout" in data and codec.layout.to_dict() != data["layout"]:
            raise SinMDMError("stored feature layout does not match the one this version derives")
        return codec


VELOCITY_UNITS = ("frame", "second")


def model_scale(codec: MotionCodec, velocity_unit: str = "frame") -> np.ndarray | None:
    """(F,) factors taking features (metres per frame) to the space a model is trained and
    sampled in; None for the paper's space (all 1). With "second" the root's horizontal
    velocity counts in metres per second: a walk's 1-3 cm per frame becomes 0.3-1, the size
    of the 6D rotation values, so the loss weighs it like them. Measured (BENCHMARKS.md):
    it moved the walk's quality balance, not its foot sliding."""
    if velocity_unit not in VELOCITY_UNITS:
        raise SinMDMError(f"unknown velocity unit {velocity_unit!r}: use one of {', '.join(VELOCITY_UNITS)}")
    if velocity_unit == "frame" or codec.trajectory_joint is None:
        return None
    scale = np.ones(codec.width)
    dx, _, dz = codec.layout.indices(("root",))
    scale[[dx, dz]] = codec.fps
    return scale


def build_codec(
    clip: BVH,
    fps: float = 30.0,
    units: str | float = "auto",
    contacts: str | list[str] = "auto",
    contact_speed: float | None = None,
    source_fps: float | None = None,
    resample: str = "slerp",
    root: str | None = None,
    up: str | None = None,
) -> MotionCodec:
    """Derive the feature codec for a clip's skeleton from the clip itself; `root`
    (a joint name) and `up` ('y' or 'z') override what rig.py detects."""
    skeleton = clip.skeleton
    scale = unit_scale(skeleton, units)
    animation = clip_animation(clip, fps, resample, source_fps)
    _check_metres(animation.translations * scale, clip_name(clip), scale)
    size = skeleton_size(skeleton) * scale

    rig = analyse_rig(animation, scale, root, up)
    trajectory = rig.trajectory_joint
    positioned = [j for j in range(skeleton.num_joints) if skeleton.position_channels(j)]
    spread = np.ptp(animation.translations * scale, axis=0).max(axis=1)  # (J,) metres
    moving = tuple(j for j in positioned if j != trajectory and j not in rig.fixed_joints and spread[j] > 1e-6 * size)
    rest = animation.translations.mean(axis=0)
    rest[list(rig.fixed_joints)] = animation.translations[0, list(rig.fixed_joints)]
    rest_rotations = animation.rotations[0] if rig.fixed_joints else None

    positions = global_positions(animation) * scale
    if contacts == "auto":
        contact_joints = tuple(detect_contact_joints(positions, fps, size, rig.up_axis))
    else:
        contact_joints = tuple(skeleton.index(name) for name in contacts)
    speed = default_contact_speed(size) if contact_speed is None else float(contact_speed)
    floors = resting_heights(positions[:, list(contact_joints)], fps, speed, rig.up_axis)
    return MotionCodec(skeleton, float(fps), scale, trajectory, moving, contact_joints, speed, rest, resample,
                       rig.up_axis, rig.height_axis, rig.fixed_joints, rest_rotations, floors)
