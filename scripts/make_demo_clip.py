"""Author the bundled example clip: "Stomper", a small keyframe-style humanoid
that walks, turns, pauses to wave and side-steps (12 s at 30 fps, cm, ZXY order).

The motion is written procedurally (smooth curves through hand-picked keys), so
the clip is original to this project. Run: python scripts/make_demo_clip.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sinmdm.runtime.bvh import BVH, Skeleton, write_bvh

FPS = 30
SECONDS = 12
OUT = Path(__file__).resolve().parents[1] / "sinmdm" / "runtime" / "demo" / "stomper.bvh"

# name, parent, offset (cm)
JOINTS = [
    ("Hips", None, (0, 92, 0)),
    ("Spine", "Hips", (0, 10, 0)),
    ("Chest", "Spine", (0, 16, 0)),
    ("Neck", "Chest", (0, 20, 0)),
    ("Head", "Neck", (0, 9, 2)),
    ("LeftArm", "Chest", (17, 16, 0)),
    ("LeftForeArm", "LeftArm", (27, 0, 0)),
    ("LeftHand", "LeftForeArm", (24, 0, 0)),
    ("RightArm", "Chest", (-17, 16, 0)),
    ("RightForeArm", "RightArm", (-27, 0, 0)),
    ("RightHand", "RightForeArm", (-24, 0, 0)),
    ("LeftUpLeg", "Hips", (9, -4, 0)),
    ("LeftLeg", "LeftUpLeg", (0, -40, 0)),
    ("LeftFoot", "LeftLeg", (0, -41, -2)),
    ("LeftToe", "LeftFoot", (0, -6, 12)),
    ("RightUpLeg", "Hips", (-9, -4, 0)),
    ("RightLeg", "RightUpLeg", (0, -40, 0)),
    ("RightFoot", "RightLeg", (0, -41, -2)),
    ("RightToe", "RightFoot", (0, -6, 12)),
]
END_SITES = {"Head": (0, 16, 0), "LeftHand": (10, 0, 0), "RightHand": (-10, 0, 0), "LeftToe": (0, 0, 6), "RightToe": (0, 0, 6)}
ORDER = "ZXY"


def keyed(times: list[float], values: list[float], t: np.ndarray) -> np.ndarray:
    """A smooth curve through keys (cosine ease between neighbours)."""
    times_a, values_a = np.asarray(times, float), np.asarray(values, float)
    k = np.clip(np.searchsorted(times_a, t, side="right") - 1, 0, len(times_a) - 2)
    u = np.clip((t - times_a[k]) / (times_a[k + 1] - times_a[k]), 0, 1)
    ease = 0.5 - 0.5 * np.cos(np.pi * u)
    return values_a[k] + (values_a[k + 1] - values_a[k]) * ease


def motion(t: np.ndarray) -> dict[str, np.ndarray]:
    """Per-joint Euler angles in degrees (z, x, y) and the root position (cm)."""
    # Gait strength: walk, slow to a stop, wave, side-step, walk again.
    gait = keyed([0, 3, 4.5, 6.5, 7.5, 9.5, 10.5, 12], [1, 1, 0, 0, 0.6, 0.6, 1, 1], t)
    cadence = keyed([0, 3, 4.5, 7.5, 9.5, 12], [1.9, 2.1, 1.6, 2.4, 1.8, 2.0], t)  # steps/s
    phase = 2 * np.pi * np.cumsum(cadence / 2) / FPS
    turn_rate = keyed([0, 2, 3, 4.5, 9.5, 10.5, 12], [0, 25, 40, 0, 0, -30, -10], t)  # deg/s
    heading = np.radians(np.cumsum(turn_rate) / FPS)
    side = keyed([0, 7.5, 8, 9.5, 10, 12], [0, 0, 1, 1, 0, 0], t)  # side-step share
    wave = keyed([0, 4.5, 5, 6.5, 7, 12], [0, 0, 1, 1, 0, 0], t)

    s, c = np.sin(phase), np.cos(phase)
    stride = 30 * gait * (1 - side)
    angles = {name: np.zeros((len(t), 3)) for name, _, _ in JOINTS}
    hip_swing = 28 * gait * s
    angles["LeftUpLeg"][:, 1] = hip_swing * (1 - side)
    angles["RightUpLeg"][:, 1] = -hip_swing * (1 - side)
    angles["LeftUpLeg"][:, 0] = 14 * side * np.maximum(s, 0)
    angles["RightUpLeg"][:, 0] = -14 * side * np.maximum(-s, 0)
    angles["LeftLeg"][:, 1] = 45 * gait * np.maximum(-c, 0) ** 2
    angles["RightLeg"][:, 1] = 45 * gait * np.maximum(c, 0) ** 2
    angles["LeftFoot"][:, 1] = 12 * gait * s
    angles["RightFoot"][:, 1] = -12 * gait * s
    angles["LeftToe"][:, 1] = 15 * gait * np.maximum(-s, 0)
    angles["RightToe"][:, 1] = 15 * gait * np.maximum(s, 0)
    angles["Spine"][:, 2] = 6 * gait * s + 4 * np.sin(0.7 * t)
    angles["Spine"][:, 1] = 5 + 3 * gait
    angles["Chest"][:, 2] = -9 * gait * s
    angles["Chest"][:, 0] = 5 * side * np.sin(phase / 2)
    angles["Head"][:, 2] = 10 * np.sin(0.5 * t) * (1 - wave) + 20 * wave
    angles["Head"][:, 1] = -4 * gait * c
    arm_swing = 30 * gait * s
    angles["LeftArm"][:, 0] = -70 + 5 * np.sin(0.9 * t)
    angles["RightArm"][:, 0] = (70 - 5 * np.sin(0.9 * t)) * (1 - wave) - 150 * wave
    angles["LeftArm"][:, 2] = arm_swing
    angles["RightArm"][:, 2] = arm_swing * (1 - wave)
    angles["LeftForeArm"][:, 2] = 20 + 10 * gait * np.maximum(s, 0)
    angles["RightForeArm"][:, 2] = (-20 - 10 * gait * np.maximum(-s, 0)) * (1 - wave) + wave * 35 * np.sin(2 * np.pi * 2.2 * t)
    angles["Hips"][:, 2] = np.degrees(heading) + 5 * gait * c  # yaw
    angles["Hips"][:, 0] = 3 * gait * s + 4 * wave * np.sin(1.5 * t)  # roll

    speed = stride * cadence / 30 * 1.8  # cm per frame, forward
    lateral = side * 2.2 * np.sin(phase / 2) ** 2
    forward = np.stack([np.sin(heading), np.cos(heading)], axis=1)
    left = np.stack([np.cos(heading), -np.sin(heading)], axis=1)
    step = forward * speed[:, None] + left * lateral[:, None]
    xz = np.cumsum(step, axis=0)
    y = 92 - 2.5 * gait * np.abs(c) - 1.5 * wave * (1 + np.sin(3 * t))
    return {"angles": angles, "root": np.stack([xz[:, 0], y, xz[:, 1]], axis=1)}


def build() -> BVH:
    names = [name for name, _, _ in JOINTS]
    parents = np.array([-1 if p is None else names.index(p) for _, p, _ in JOINTS])
    offsets = np.array([o for _, _, o in JOINTS], dtype=float)
    rot = tuple(f"{axis}rotation" for axis in ORDER)
    channels = tuple((("Xposition", "Yposition", "Zposition") + rot) if p is None else rot for _, p, _ in JOINTS)
    end_sites = tuple((names.index(n), np.array(o, dtype=float)) for n, o in END_SITES.items())
    skeleton = Skeleton(names=tuple(names), parents=parents, offsets=offsets, channels=channels, end_sites=end_sites)

    t = np.arange(SECONDS * FPS) / FPS
    m = motion(t)
    angles = np.concatenate([m["angles"][name] for name in names], axis=1)  # (z, x, y) = ZXY channel order
    root = plant_feet(skeleton, angles)
    return BVH(skeleton, 1.0 / FPS, np.concatenate([root, angles], axis=1))


def plant_feet(skeleton: Skeleton, angles: np.ndarray) -> np.ndarray:
    """Root path that keeps the lower foot where it is (no sliding) and on the floor."""
    from sinmdm.runtime.animation import animation_from_bvh, global_positions

    still = BVH(skeleton, 1.0 / FPS, np.concatenate([np.zeros((len(angles), 3)), angles], axis=1))
    positions = global_positions(animation_from_bvh(still))
    toes = [skeleton.names.index("LeftToe"), skeleton.names.index("RightToe")]
    feet = positions[:, toes]  # (T, 2, 3), root at the origin
    stance = np.argmin(feet[:, :, 1], axis=1)
    foot = feet[np.arange(len(feet)), stance]
    step = np.zeros_like(foot)
    # While the same foot stands, the root moves opposite to that foot's motion.
    same = stance[1:] == stance[:-1]
    step[1:][same] = -(foot[1:] - feet[np.arange(len(feet) - 1), stance[1:]][:, :])[same]
    step[1:][~same] = step[:-1][~same]
    xz = np.cumsum(step[:, [0, 2]], axis=0)
    y = -feet[:, :, 1].min(axis=1) + 1.0
    return np.stack([xz[:, 0], y, xz[:, 1]], axis=1)


if __name__ == "__main__":
    OUT.parent.mkdir(parents=True, exist_ok=True)
    write_bvh(OUT, build())
    print(f"wrote {OUT}")
