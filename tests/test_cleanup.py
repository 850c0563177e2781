"""Foot-contact cleanup (runtime/cleanup.py): planted feet stop sliding, nothing else moves."""

from __future__ import annotations

import hashlib
import json
from dataclasses import replace

import numpy as np
import pytest

from sinmdm.eval.plausibility import plausibility
from sinmdm.runtime import SamplingOptions, generate, load_model, read_bvh
from sinmdm.runtime.animation import Animation, animation_from_bvh, animation_to_bvh, global_positions
from sinmdm.runtime import cleanup
from sinmdm.runtime.cleanup import cleanup_contacts, contact_intervals, contact_offsets, trim_fast_ends
from sinmdm.runtime.features import MotionCodec, build_codec

from .conftest import DEMO_CLIP, real_clip, run_cli
from .layouts import z_up


@pytest.fixture(scope="module")
def demo():
    model = load_model()
    plain = generate(model, 240, SamplingOptions(count=4, seed=3, cleanup=False))
    cleaned = generate(model, 240, SamplingOptions(count=4, seed=3))
    return model, plain, cleaned


def test_intervals_and_fades():
    labels = np.array([0, 1, 1, 1, 0, 1, 0, 0, 1, 1])
    assert contact_intervals(labels) == [(1, 4), (8, 10)]  # the single frame is noise
    positions = np.zeros((30, 3))
    positions[:, 0] = np.arange(30) * 0.1  # a foot sliding along x
    positions[:, 1] = 0.02 * np.sin(np.arange(30))  # and bobbing on the floor
    inside = np.zeros(30, dtype=bool)
    inside[10:20] = True
    anchor, weight = contact_offsets(positions, inside)
    pinned = positions + weight[:, None] * anchor
    assert np.allclose(pinned[10:20], positions[10:20].mean(axis=0))  # planted at the run's mean, height too
    assert weight[10:20].min() == 1 and weight[[0, -1]].max() < 0.25
    assert np.all(np.diff(weight[:11]) > 0) and np.all(np.diff(weight[19:]) < 0)  # eased in and out, no ringing
    # The old 4-frame cosine fade of the offset stopped the foot from its full sampled speed (0.1 a
    # frame) in one frame; eased, it slows before landing and picks up after lifting off.
    assert np.abs(np.diff(np.diff(pinned[:, 0]))).max() < 0.085
    far = np.zeros((80, 3))
    far[:, 0] = np.arange(80) * 0.1
    run = np.zeros(80, dtype=bool)
    run[35:45] = True
    assert contact_offsets(far, run)[1][[*range(5), *range(75, 80)]].max() == 0  # untouched far from the run


def test_a_lowering_pin_lets_go_of_the_swing_sooner_than_a_raise(monkeypatch):
    # A toe descending from 7 cm when its label comes on (frame 10), on the floor from frame 13.
    height = np.concatenate([np.linspace(2.0, 7.0, 6), np.linspace(7.0, 1.0, 8)[1:], np.ones(10)]) / 100
    positions = np.stack([np.zeros_like(height), height, np.zeros_like(height)], axis=1)
    inside = np.arange(len(height)) >= 10
    anchor, weight = contact_offsets(positions, inside)
    lowered, _ = contact_offsets(positions, inside, up=1)
    before = weight[:10, None] * anchor[:10]
    eased = weight[:10] * lowered[:10, 1]
    assert np.allclose(lowered[inside], anchor[inside])  # the pin itself is the same
    assert eased.min() < 0 and np.all(eased >= before[:, 1] - 1e-12)  # lowers the swing less
    assert abs(eased[5]) < 0.25 * abs(before[5, 1])  # the swing's top, 5 frames out: nearly untouched
    flat = np.zeros_like(positions)  # a foot sampled 2 cm under its resting height: the pin raises it
    raised, w_raised = contact_offsets(flat, inside, up=1, floor=0.02)
    monkeypatch.setattr(cleanup, "LOWER_EASE", cleanup.EASE_FRAMES)  # every offset eased as before the rule
    raise_only, w_raise = contact_offsets(flat, inside, up=1, floor=0.02)
    assert np.allclose(raised * w_raised[:, None], raise_only * w_raise[:, None])  # a raise eases as before
    assert (raised[:10, 1] * w_raised[:10])[-3:].min() > 0.005


def test_a_label_on_before_landing_or_after_lift_off_is_trimmed():
    # x: a foot arriving at 0.2 a frame, resting on frames 4-9, leaving at 0.2 a frame
    x = np.array([0.0, 0.2, 0.4, 0.6, 0.8, 0.8, 0.8, 0.8, 0.8, 0.81, 1.0, 1.2, 1.4])
    positions = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1)
    inside = np.zeros(len(x), dtype=bool)
    inside[2:12] = True  # the label: on two frames early, two late
    assert contact_intervals(trim_fast_ends(inside, positions, 0.05)) == [(4, 10)]
    assert not trim_fast_ends(np.arange(len(x)) < 3, positions, 0.05).any()  # all in flight: no contact
    still = np.zeros_like(positions)
    assert (trim_fast_ends(inside, still, 0.05) == inside).all()


def test_a_ball_under_a_planted_ankle_is_pinned_a_foot_away_from_it():
    """A sliding foot planted heel first: the ankle's run (frames 10-20) and the ball's (15-30)
    are different spans of the slide, so their own means lie further apart than the foot is
    long (the ball could not reach its pin and the toe bent down to its own). Carried by the
    ankle's offset over the frames they share, the ball's pin keeps the foot's length."""
    frames = np.arange(40)
    ankle = np.zeros((40, 3))
    ankle[:, 0] = 0.1 * frames
    ankle[:, 1] = 0.1
    ball = ankle + [0.15, -0.08, 0.0]  # a rigid foot sliding along x
    ankle_in, ball_in = np.zeros(40, dtype=bool), np.zeros(40, dtype=bool)
    ankle_in[10:20], ball_in[15:30] = True, True
    ankle_anchor, _ = contact_offsets(ankle, ankle_in)
    own, _ = contact_offsets(ball, ball_in)
    carried, weight = contact_offsets(ball, ball_in, carried=np.where(ankle_in[:, None], ankle_anchor, np.nan))
    ankle_pin, own_pin, ball_pin = ankle[12] + ankle_anchor[12], ball[20] + own[20], ball[20] + carried[20]
    assert np.linalg.norm(own_pin - ankle_pin) > 0.5  # own means: 1 m apart on a 17 cm foot
    assert np.allclose(ball_pin - ankle_pin, [0.15, -0.08, 0.0])
    assert np.allclose(ball[15:30] + carried[15:30], ball_pin) and weight[15:30].min() == 1  # one pin per run


def test_a_foot_landing_is_not_aimed_under_the_floor():
    """Before a contact the toe aim's goal is the sampled position moved by the offset at the
    run's first frame. A foot that lands toes up (its ball above the run's mean for the first
    frames) made that goal lie below the floor, and the ankle turned the toes into it (2 cm
    under on the real walk, 10 cm on sampled walks). The goal now stays no lower than the
    sample's own height or the lowest pin: the cleaned toes go no deeper than the sample."""
    from sinmdm.runtime.cleanup import axis_angle_matrix
    from sinmdm.runtime.kinematics import forward_kinematics

    bvh = read_bvh(real_clip("Joe_Walk-In-Circle.bvh"))
    codec = build_codec(bvh)
    features = codec.encode(bvh)
    animation = codec.decode(features)
    names, parents, contacts = animation.skeleton.names, animation.skeleton.parents, list(codec.contact_joints)
    labels = features[:, codec.layout.indices(("contact",))]
    glob, pos = forward_kinematics(animation.rotations, animation.translations, parents)
    rotations = animation.rotations.copy()
    for side in ("Left", "Right"):
        foot, ball = (next(j for j, n in enumerate(names) if n.endswith(side + part)) for part in ("Foot", "ToeBase"))
        for start, _ in contact_intervals(labels[:, contacts.index(ball)]):
            for t in range(start, min(start + 2, animation.frames)):  # land toes up: the ball 0.5 rad high
                forward = pos[t, ball] - pos[t, foot]
                forward[1] = 0.0
                lift = axis_angle_matrix(np.cross(forward, [0.0, 1.0, 0.0]) / np.linalg.norm(forward), np.array(0.5))
                parent = glob[t, parents[foot]]
                rotations[t, foot] = parent.T @ lift @ parent @ rotations[t, foot]
    landing = Animation(animation.skeleton, rotations, animation.translations, animation.fps)
    ends = [j for j, n in enumerate(names) if n.endswith("Toe_End")]
    before = global_positions(landing)[:, ends, 1].min()
    after = global_positions(cleanup_contacts(landing, codec, features))[:, ends, 1].min()
    assert after >= before - 0.5  # cm; before the bound: 2.1 cm under the floor the sample never goes below


def test_cleanup_removes_sliding_on_the_demo_model(demo):
    """On sampled motion the planted feet slide several times the clip's own speed; after the
    cleanup they slide no more than the clip (plus the verdict's slack)."""
    model, plain, cleaned = demo
    reference = read_bvh(DEMO_CLIP)
    before = plausibility(reference, plain.clips)["aggregate"]
    after = plausibility(reference, cleaned.clips)["aggregate"]
    clip = after["clip_foot_skating_cm_s"]
    assert before["foot_skating_cm_s"] > 4 * clip
    assert after["foot_skating_cm_s"] < 1.5 * clip
    assert after["foot_skating_cm_s"] < before["foot_skating_cm_s"] / 4
    assert after["root_step_max_ratio"] <= 1.1 * max(before["root_step_max_ratio"], 1.0)  # no new jumps


def _bob_while_planted_cm_s(model, clips) -> float:
    """Mean vertical speed of the contact joints on frames where they stand still
    horizontally (slower than the codec's contact speed)."""
    codec = model.codec
    flat = list(codec.horizontal_axes)
    speeds = []
    for clip in clips:
        feet = global_positions(animation_from_bvh(clip))[:, list(codec.contact_joints)] * codec.scale
        velocity = np.diff(feet, axis=0) * codec.fps
        planted = np.linalg.norm(velocity[..., flat], axis=-1) < codec.contact_speed
        speeds.append(np.abs(velocity[..., codec.up_axis])[planted])
    return float(np.concatenate(speeds).mean() * 100)


def test_planted_feet_stop_bobbing(demo):
    """A planted foot is held at its run's mean height: sampled feet rise and fall while
    they stand (the crab's 10 cm/s, BENCHMARKS.md); cleaned ones hardly move."""
    model, plain, cleaned = demo
    before, after = _bob_while_planted_cm_s(model, plain.clips), _bob_while_planted_cm_s(model, cleaned.clips)
    assert after < before / 2


def _planted_heights(model, clips) -> list[np.ndarray]:
    """Per contact joint: its heights (metres) on frames where it stands still horizontally."""
    codec = model.codec
    feet = np.concatenate([global_positions(animation_from_bvh(c))[:, list(codec.contact_joints)] for c in clips]) * codec.scale
    speed = np.linalg.norm(np.diff(feet, axis=0)[..., list(codec.horizontal_axes)], axis=-1) * codec.fps
    return [feet[1:, k, codec.up_axis][speed[:, k] < codec.contact_speed] for k in range(feet.shape[1])]


def test_planted_feet_are_lifted_to_the_clips_resting_height(demo):
    """A model that samples a planted foot low is pinned in the floor; with the clip's resting
    heights (codec.contact_floors, measured at training) no pin lies below them, and a swinging
    foot that dips under them is raised. Here floors 3 cm above where the demo's cleaned feet
    stand: the feet come up to them."""
    model, _, cleaned = demo
    assert model.codec.contact_floors is None  # the demo predates the field: pins as sampled
    floors = [float(np.median(h)) + 0.03 for h in _planted_heights(model, cleaned.clips)]
    lifted = replace(model, codec=replace(model.codec, contact_floors=tuple(floors)))
    raised = generate(lifted, 240, SamplingOptions(count=4, seed=3))
    for before, after, floor in zip(_planted_heights(model, cleaned.clips), _planted_heights(lifted, raised.clips), floors):
        assert np.mean(before < floor - 0.005) > 0.4
        assert np.mean(after < floor - 0.005) < 0.1
    # off the contacts too: a swinging foot that dips under its resting height is raised to it
    codec = model.codec
    heights = np.concatenate([global_positions(animation_from_bvh(c))[:, list(codec.contact_joints), codec.up_axis]
                              for c in raised.clips]) * codec.scale
    assert np.mean(heights < np.array(floors) - 0.005) < 0.01


def test_the_clips_resting_heights_are_measured_at_training():
    codec = build_codec(read_bvh(real_clip("Joe_Walk-In-Circle.bvh")))
    floors = dict(zip((codec.skeleton.names[j].split(":")[-1] for j in codec.contact_joints), codec.contact_floors))
    assert 0.015 < floors["LeftToeBase"] < 0.025 and 0.10 < floors["LeftFoot"] < 0.13  # toes on the floor, ankles above
    assert MotionCodec.from_dict(codec.to_dict()).contact_floors == codec.contact_floors
    upright = build_codec(z_up(read_bvh(real_clip("Joe_Walk-In-Circle.bvh"))))  # heights along Z there
    assert upright.up_axis == 2 and np.allclose(upright.contact_floors, codec.contact_floors, atol=1e-9)


def test_root_is_slowed_to_the_planted_feet_within_the_contact_speed(demo):
    """Only the trajectory joint's translation changes: horizontally by at most the contact
    speed per frame, smoothly (no step in the root's speed); vertically only down (the hips
    lowered where a leg cannot reach its pin), by at most MAX_DROP of the leg, smoothly."""
    from sinmdm.runtime.cleanup import MAX_DROP

    model, plain, cleaned = demo
    codec = model.codec
    limit = codec.contact_speed / codec.fps / codec.scale
    leg = 92.0  # the demo's hips height over the floor, file units
    lowered = 0
    for a, b in zip(plain.clips, cleaned.clips):
        before, after = animation_from_bvh(a), animation_from_bvh(b)
        delta = after.translations - before.translations
        others = [j for j in range(before.skeleton.num_joints) if j != codec.trajectory_joint]
        np.testing.assert_array_equal(delta[:, others], 0.0)
        root = delta[:, codec.trajectory_joint]
        drop = -root[:, codec.up_axis]
        assert drop.min() > -1e-9 and drop.max() <= MAX_DROP * leg
        assert np.abs(np.diff(drop, n=2)).max() < 0.2 * max(drop.max(), 1e-9)
        lowered += drop.max() > 1e-6
        flat = np.delete(root, codec.up_axis, axis=1)
        assert np.linalg.norm(np.diff(flat, axis=0), axis=-1).max() <= limit * (1 + 1e-6)
        assert np.linalg.norm(np.diff(flat, n=2, axis=0), axis=-1).max() < 0.5 * limit
    assert lowered  # the demo's stomps plant feet beyond the sampled legs' reach


def test_only_leg_rotations_change_and_bones_keep_their_length(demo):
    model, plain, cleaned = demo
    codec = model.codec
    for a, b in zip(plain.clips, cleaned.clips):
        before, after = animation_from_bvh(a), animation_from_bvh(b)
        before = Animation(before.skeleton, before.rotations, after.translations, before.fps)  # the root's move aside
        p, q = global_positions(before), global_positions(after)
        parents = before.skeleton.parents
        child = np.arange(1, len(parents))
        np.testing.assert_allclose(np.linalg.norm(q[:, child] - q[:, parents[child]], axis=-1),
                                   np.linalg.norm(p[:, child] - p[:, parents[child]], axis=-1), atol=1e-3)
        moved = np.abs(q - p).max(axis=(0, 2)) > 1e-6
        legs = set()  # the joints between the trajectory joint and a contact joint, and all below them
        for j in codec.contact_joints:
            legs |= set(_chain(parents, j)) - set(_chain(parents, codec.trajectory_joint))
        legs = {j for j in range(len(parents)) if set(_chain(parents, j)) & legs}
        assert set(np.flatnonzero(moved)) <= legs and moved.any()


def _chain(parents, joint):
    out = []
    while joint >= 0:
        out.append(joint)
        joint = parents[joint]
    return out


def test_without_contacts_nothing_changes(demo):
    model, plain, _ = demo
    features = plain.features[0].copy()
    features[:, model.codec.layout.indices(("contact",))] = 0.0
    animation = model.codec.decode(features)
    out = cleanup_contacts(animation, model.codec, features)
    np.testing.assert_array_equal(out.rotations, animation.rotations)


@pytest.mark.parametrize("name", ["Joe_Walk-In-Circle.bvh", "Xia_normal.bvh"])
def test_cleanup_is_the_same_on_a_z_up_export(name):
    """A slid copy of a real clip is pinned back the same way whether the file is Y-up or Z-up:
    the cleanup keeps the up axis' height and only moves the feet on the floor plane."""
    results = []
    for bvh in (read_bvh(real_clip(name)), z_up(read_bvh(real_clip(name)))):
        codec = build_codec(bvh)
        features = codec.encode(bvh)
        animation = codec.decode(features)
        out = cleanup_contacts(animation, codec, features)
        p, q = global_positions(animation), global_positions(out)
        feet = list(codec.contact_joints)
        results.append((codec.up_axis, q[:, feet] - p[:, feet]))
    (up_y, moved_y), (up_z, moved_z) = results
    assert (up_y, up_z) == (1, 2)
    rotated = moved_y @ np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]).T
    np.testing.assert_allclose(moved_z, rotated, atol=1e-3 * np.abs(moved_y).max() + 1e-6)


def test_cleanup_never_makes_a_real_clip_slide_more():
    """The training clip itself, with its own contact labels: pinning keeps it as good as it was."""
    bvh = read_bvh(real_clip("Joe_Walk-In-Circle.bvh"))
    codec = build_codec(bvh)
    features = codec.encode(bvh)
    animation = codec.decode(features)
    out = cleanup_contacts(animation, codec, features)
    before = plausibility(bvh, [codec.decode_bvh(features)])["aggregate"]["foot_skating_cm_s"]
    after = plausibility(bvh, [animation_to_bvh(out)])["aggregate"]["foot_skating_cm_s"]
    assert after <= before + 0.1


def _digest(path) -> str:
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


def test_cli_cleanup_flag_and_determinism(tmp_path, no_torch_env):
    runs = {}
    for tag, extra in (("a", []), ("b", []), ("off", ["--no-cleanup"])):
        result = run_cli("sinmdm-run", "sample", "--seconds", "3", "--steps", "8", "--seed", "2", "--json",
                         "--out", str(tmp_path / tag), *extra, env=no_torch_env, check=True)
        runs[tag] = json.loads(result.stdout)
    assert runs["a"]["cleanup"] is True and runs["off"]["cleanup"] is False
    assert _digest(runs["a"]["files"][0]) == _digest(runs["b"]["files"][0])
    assert _digest(runs["a"]["files"][0]) != _digest(runs["off"]["files"][0])
    result = run_cli("sinmdm-run", "inbetween", "--ref", str(DEMO_CLIP), "--steps", "4", "--no-cleanup", "--json",
                     "--out", str(tmp_path / "inb"), env=no_torch_env, check=True)
    assert json.loads(result.stdout)["cleanup"] is False


def _turn_angles(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angles (radians) of the rotations taking a to b, (..., 3, 3) each."""
    relative = np.swapaxes(a, -1, -2) @ b
    return np.arccos(np.clip((np.trace(relative, axis1=-2, axis2=-1) - 1) / 2, -1, 1))


def test_a_many_jointed_leg_is_pinned_by_small_turns_over_its_whole_chain():
    """The crab's legs have five rotating joints: one damped-least-squares solve over all of
    them reaches the pin with turns a fraction of what bending the last two joints takes (the
    rotations the paper's metrics compare stay near the model's), keeps every bone's length
    and never twists a bone about itself."""
    from sinmdm.runtime.cleanup import _solve_chain, find_legs, two_bone_ik, _hinge_axes
    from sinmdm.runtime.kinematics import chain_kinematics

    bvh = read_bvh(real_clip("Crabnew_Crab-dance-long.bvh"))
    codec = build_codec(bvh)
    animation = codec.decode(codec.encode(bvh))
    parents = animation.skeleton.parents
    positions = global_positions(animation)
    legs = find_legs(animation, codec, positions)
    assert len(legs) == 6 and all(len(leg.chain) == 5 for leg in legs)
    leg = legs[0]
    target = positions[:, leg.effector] + np.array([0.03, 0.0, -0.02])  # 3.6 cm on the floor (Y-up)
    local = animation.rotations.copy()
    _solve_chain(local, animation.translations, parents, leg, target)
    _, reached = chain_kinematics(local, animation.translations, parents, [leg.effector])
    miss = np.linalg.norm(reached[:, 0] - target, axis=-1)
    chain = positions[:, [*leg.chain, leg.effector]]
    reach = np.linalg.norm(np.diff(chain, axis=1), axis=-1).sum(axis=1)
    inside = np.linalg.norm(target - chain[:, 0], axis=-1) < 0.95 * reach  # the crab's legs are near straight
    assert inside.mean() > 0.5 and miss[inside].max() < 1e-4
    assert np.all(miss[~inside] <= 0.036 + 1e-6)  # out of reach: as near as the chain goes, never further
    turned = _turn_angles(animation.rotations[:, list(leg.chain)], local[:, list(leg.chain)])
    _, before = chain_kinematics(animation.rotations, animation.translations, parents, [*leg.chain, leg.effector])
    _, after = chain_kinematics(local, animation.translations, parents, [*leg.chain, leg.effector])
    np.testing.assert_allclose(np.linalg.norm(np.diff(after, axis=1), axis=-1),
                               np.linalg.norm(np.diff(before, axis=1), axis=-1), atol=1e-6)
    # the same pin by the last two joints alone (what a human's leg gets)
    hip, knee = leg.chain[-2], leg.chain[-1]
    glob, pos = chain_kinematics(animation.rotations, animation.translations, parents, [hip, knee, leg.effector])
    hinge = _hinge_axes(pos[:, 0], pos[:, 1], pos[:, 2], glob[:, 0])
    hip_world, knee_world = two_bone_ik(pos[:, 0], pos[:, 1], pos[:, 2], target, hinge)
    two_bone = np.maximum(_turn_angles(np.eye(3), hip_world), _turn_angles(np.eye(3), hip_world @ knee_world))
    assert np.median(turned.max(axis=1)) < 0.5 * np.median(two_bone)


def test_a_toe_turns_at_most_pivot_turn_to_reach_its_pin():
    """A toe whose pin lies behind it (the ankle pinned to one mean, the toe's end to another)
    was swung round by up to 100 degrees, bent backwards past anything the clip does: each
    aim is now capped, the rest is left to slide. The real walk with its toes wobbled by up
    to 46 degrees a frame: every toe turn stays under the cap, and the feet still slide less."""
    from sinmdm.runtime.cleanup import PIVOT_TURN, axis_angle_matrix

    bvh = read_bvh(real_clip("Joe_Walk-In-Circle.bvh"))
    codec = build_codec(bvh)
    features = codec.encode(bvh)
    animation = codec.decode(features)
    toes = [j for j, name in enumerate(animation.skeleton.names) if name.endswith("ToeBase")]
    assert len(toes) == 2 and set(toes) <= set(codec.contact_joints)
    rng = np.random.default_rng(0)
    axes = rng.normal(size=(animation.frames, len(toes), 3))
    axes /= np.linalg.norm(axes, axis=-1, keepdims=True)
    rotations = animation.rotations.copy()
    rotations[:, toes] = rotations[:, toes] @ axis_angle_matrix(axes, rng.uniform(0, 0.8, (animation.frames, len(toes))))
    wobbled = Animation(animation.skeleton, rotations, animation.translations, animation.fps)
    out = cleanup_contacts(wobbled, codec, features)
    assert _turn_angles(rotations[:, toes], out.rotations[:, toes]).max() <= PIVOT_TURN + 1e-6
    before, after = (plausibility(bvh, [animation_to_bvh(a)])["aggregate"]["foot_skating_cm_s"] for a in (wobbled, out))
    assert after < 0.8 * before
