"""The plausibility metrics see what the paper's cannot: a clip against itself is
neutral, a teleport, a backward walk and a sunken figure are each named."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sinmdm.eval.plausibility import plausibility
from sinmdm.runtime.animation import Animation, animation_from_bvh, animation_to_bvh
from sinmdm.runtime.bvh import BVH, read_bvh, write_bvh
from sinmdm.runtime.features import build_codec
from sinmdm.runtime.rotations import axis_matrix

from .conftest import real_clip, run_cli
from .layouts import z_up


@pytest.fixture(scope="module")
def walk():
    return read_bvh(real_clip("Joe_Walk-In-Circle.bvh"))


def _leg_columns(clip: BVH) -> list[slice]:
    """The motion columns of each leg joint (hips to toes) of a Mixamo clip."""
    start = np.cumsum([0, *(len(c) for c in clip.skeleton.channels)])
    return [slice(start[j], start[j + 1]) for j, n in enumerate(clip.skeleton.names)
            if any(k in n for k in ("UpLeg", "Leg", "Foot", "Toe"))]


def _edited(clip: BVH, edit) -> BVH:
    values = clip.values.copy()
    edit(values)
    return BVH(clip.skeleton, clip.frame_time, values)


def test_a_clip_against_itself_is_neutral(walk):
    row = plausibility(walk, [walk])["samples"][0]
    assert row["root_step_max_ratio"] == pytest.approx(1, abs=1e-9)
    assert row["jitter_ratio"] == pytest.approx(1, abs=1e-9) and row["speed_distance_m_s"] == 0
    assert row["backward_share"] == row["clip_backward_share"] and row["verdict"] == "plausible"
    assert row["foot_skating_cm_s"] == row["clip_foot_skating_cm_s"]
    assert row["foot_bob_cm_s"] == row["clip_foot_bob_cm_s"]
    assert row["turning_distance_deg_s"] == 0 and row["turning_deg_s"] == row["clip_turning_deg_s"]
    assert row["foot_lift_cm"] == row["clip_foot_lift_cm"] > 5 and row["lift_judged"]


def test_a_teleport_is_named_with_its_frame(walk):
    def jump(values):
        values[400:, 0] += 50.0  # 50 cm along x from frame 400 (60 fps) on
    row = plausibility(walk, [_edited(walk, jump)])["samples"][0]
    assert row["verdict"].startswith("teleports") and "frame 200" in row["verdict"]  # 30 fps frame


def test_a_smooth_motion_faster_than_the_clip_is_not_called_a_teleport(walk):
    fast = BVH(walk.skeleton, walk.frame_time, walk.values[::2].copy())  # every step twice as long
    row = plausibility(walk, [fast])["samples"][0]
    assert row["root_step_max_ratio"] > 1.5 and row["worst_step_contrast"] < 3
    assert row["verdict"].startswith("root too fast")


def test_walking_backwards_is_named(walk):
    reversed_walk = BVH(walk.skeleton, walk.frame_time, walk.values[::-1].copy())
    row = plausibility(walk, [reversed_walk])["samples"][0]
    assert row["backward_share"] > 0.8 and "backwards" in row["verdict"]


def test_a_sunken_figure_is_named(walk):
    def lower(values):
        values[:, 1] -= 10.0  # 10 cm
    row = plausibility(walk, [_edited(walk, lower)])["samples"][0]
    assert "floor" in row["verdict"] and row["penetration_cm"] > 5


def test_a_joint_the_clip_itself_puts_through_the_floor_is_judged_against_the_clip():
    # the crab's clip dips its right claw's tip 4 cm under its floor: no flaw of a sample that does the same
    crab = read_bvh(real_clip("Crabnew_Crab-dance-long.bvh"))
    row = plausibility(crab, [crab])["samples"][0]
    assert row["penetration_cm"] == 0 and row["penetration_share"] == 0 and row["verdict"] == "plausible"

    def deeper(values):  # the whole crab 5 cm lower: its feet and its claw go deeper than the clip's
        values[:, 1] -= 0.05  # the crab is in metres
    row = plausibility(crab, [_edited(crab, deeper)])["samples"][0]
    assert row["verdict"].startswith("sinks") and row["penetration_share"] > 0.5


def test_a_dip_on_a_few_frames_is_named_with_a_share_above_zero(walk):
    def dip(values):  # the whole figure down 6 cm at frame 300 (60 fps), eased over a few frames: no jump
        values[:, 1] -= 6.0 * np.exp(-0.5 * ((np.arange(len(values)) - 300) / 2.0) ** 2)
    row = plausibility(walk, [_edited(walk, dip)])["samples"][0]
    assert 0 < row["penetration_share"] < 0.01
    assert row["verdict"].startswith("sinks") and f"{100 * row['penetration_share']:.1f} % of frames" in row["verdict"]


def test_feet_that_never_stop_are_named(walk):
    """The legs held in one pose while the body travels as in the clip: the feet glide along with
    it, never planted, yet there is nothing to skate on planted frames, no pace or turning change."""
    def freeze(values):
        for columns in _leg_columns(walk):
            values[:, columns] = values[0, columns]
    row = plausibility(walk, [_edited(walk, freeze)])["samples"][0]
    assert row["planted_share"] < 0.5 * row["clip_planted_share"]
    assert row["verdict"].startswith("feet glide"), row["verdict"]
    itself = plausibility(walk, [walk])["samples"][0]
    assert itself["planted_share"] == itself["clip_planted_share"] and itself["verdict"] == "plausible"


def test_feet_that_shuffle_are_named(walk):
    """The legs' rotations pulled most of the way to their mean pose: the feet still step and plant,
    the body travels as in the clip, but they lift about half as high (what the Z-up walk's kept
    checkpoint did, BENCHMARKS.md "Feet that shuffle")."""
    def damp(values):
        for columns in _leg_columns(walk):
            part = values[:, columns]
            values[:, columns] = part.mean(axis=0) + 0.4 * (part - part.mean(axis=0))
        values[:, 1] += 3.0  # the damped legs reach 2 cm lower on average: the hips up by 3 (cm)
    row = plausibility(walk, [_edited(walk, damp)])["samples"][0]
    assert row["foot_lift_cm"] < 0.7 * row["clip_foot_lift_cm"]
    assert row["verdict"].startswith("feet shuffle"), row["verdict"]


def test_feet_that_barely_lift_in_the_clip_are_not_judged():
    elephant = read_bvh(real_clip("Elephant_idle1.bvh"))
    row = plausibility(elephant, [elephant])["samples"][0]
    assert not row["lift_judged"] and row["verdict"] == "plausible"


def test_eval_reports_plausibility(tmp_path, walk):
    sample = tmp_path / "s.bvh"
    write_bvh(sample, walk)
    out = json.loads(run_cli("sinmdm", "eval", str(real_clip("Joe_Walk-In-Circle.bvh")), str(sample), "--json",
                             check=True).stdout)
    assert out["plausibility"]["aggregate"]["implausible"] == 0


def test_mixamo24_follows_the_papers_unit_rule(walk, tmp_path):
    from sinmdm.eval.motion_features import eval_features, paper_scale, protocol_for
    from .layouts import scaled

    for name in ("Joe_Walk-In-Circle.bvh", "Joe_Baseball-Milling-Idle.bvh"):
        clip = read_bvh(real_clip(name))
        hips = clip.skeleton.index("mixamorig7:Hips")
        expected = 0.01 if clip.skeleton.offsets[hips, 1] > 10 else 1.0
        assert protocol_for(clip, "mixamo24").scale == paper_scale(clip.skeleton) == expected
    metres = scaled(walk, 0.01)  # Hips OFFSET y now below 10: taken as metres, no 1/100
    assert paper_scale(metres.skeleton) == 1.0 and paper_scale(walk.skeleton) == 0.01
    protocol = protocol_for(walk, "mixamo24")
    cm_labels, m_labels = eval_features(walk, protocol)[:, -4:], eval_features(metres, protocol)[:, -4:]
    assert np.array_equal(cm_labels, m_labels)


def test_the_papers_protocol_is_chosen_only_where_its_unit_rule_reads_the_figure_right(walk):
    from sinmdm.eval.balance import eval_preset
    from .layouts import scaled, with_static_root, z_up

    assert eval_preset(walk) == "mixamo24" and eval_preset(scaled(walk, 0.01)) == "mixamo24"  # cm and m
    # Z-up under a static root: the Hips OFFSET y is 0, the rule would read the 1.8 m walk as 180 m
    assert eval_preset(z_up(with_static_root(walk))) == "default"
    assert eval_preset(read_bvh(real_clip("Xia_proud.bvh"))) == "default"  # not Mixamo names


def test_a_recombination_of_the_clips_own_halves_is_not_called_backwards():
    """The crab's dance walks one way for its first 100 frames, back and forth for the next 170
    and stands for the rest: its middle played twice walks backwards far more often than the
    whole clip does, and is still the clip's own motion. The verdict compares with the most
    any half of the clip has; a clip that only walks forwards (the walk above) allows nothing."""
    crab = read_bvh(real_clip("Crabnew_Crab-dance-long.bvh"))
    middle = crab.values[90:280]
    twice = np.concatenate([middle, middle])
    twice[len(middle) :, :3] += middle[-1, :3] - middle[0, :3]  # the second pass starts where the first ends
    row = plausibility(crab, [BVH(crab.skeleton, crab.frame_time, twice)])["samples"][0]
    assert row["backward_share"] > row["clip_backward_share"] + 0.05
    assert row["clip_backward_half_max"] > row["backward_share"] - 0.05
    assert "backwards" not in row["verdict"]


def _yawed(clip: BVH, angles) -> BVH:
    """The clip with its root turned about the up axis by `angles(animation)` (radians per frame),
    its path turned with it where it stands."""
    animation = animation_from_bvh(clip)
    turn = axis_matrix(1, angles(animation))
    rotations = animation.rotations.copy()
    rotations[:, 0] = turn @ rotations[:, 0]
    translations = animation.translations.copy()
    step = np.einsum("tab,tb->ta", turn[1:], np.diff(translations[:, 0], axis=0))
    translations[1:, 0] = translations[0, 0] + np.cumsum(step, axis=0)
    return animation_to_bvh(Animation(clip.skeleton, rotations, translations, animation.fps))


def _straightened(clip: BVH) -> BVH:
    """The clip with its root's turning taken out: the same gait walked along a straight line."""
    def undo(animation):
        facing = animation.rotations[:, 0] @ np.array([0.0, 0.0, 1.0])
        heading = np.unwrap(np.arctan2(facing[:, 0], facing[:, 2]))
        return heading[0] - heading
    return _yawed(clip, undo)


def test_a_walk_that_stops_turning_is_named(walk):
    """The walk turns a full circle to the left; the same gait on a straight line loses what the speed distance
    and the paper's metrics cannot see: its path."""
    row = plausibility(walk, [_straightened(walk)])["samples"][0]
    assert row["clip_turning_deg_s"] == pytest.approx(30, abs=3) and abs(row["turning_deg_s"]) < 2
    assert row["speed_distance_m_s"] < 0.02
    assert row["verdict"].startswith("turns unlike the clip") and row["turning_distance_deg_s"] > 25


def test_turning_is_the_same_on_a_z_up_copy(walk):
    row = plausibility(z_up(walk), [z_up(walk)])["samples"][0]
    assert row["clip_turning_deg_s"] == pytest.approx(plausibility(walk, [walk])["samples"][0]["clip_turning_deg_s"])
    assert row["turning_distance_deg_s"] == 0 and row["verdict"] == "plausible"


def _turned_round(clip: BVH, at: int, frames: int) -> BVH:
    """The clip with the character whipped round 180 degrees over `frames` frames from `at` on."""
    return _yawed(clip, lambda animation: np.pi * np.clip((np.arange(animation.frames) - at) / frames, 0.0, 1.0))


def test_a_spin_is_named_with_its_frame(walk):
    row = plausibility(walk, [_turned_round(walk, at=300, frames=6)])["samples"][0]  # 60 fps: 0.1 s
    assert row["fastest_turn_deg_s"] > 5 * row["clip_fastest_turn_deg_s"]
    assert row["verdict"].startswith("spins") and "frame 15" in row["verdict"]  # at 30 fps, ends by frame 153-158


def _slowed(clip: BVH, factor: float) -> BVH:
    """The clip with its root's travel over the ground scaled by `factor` (the same gait, shorter strides)."""
    up = build_codec(clip).up_axis
    values = np.array(clip.values, dtype=np.float64)
    for axis in (a for a in range(3) if a != up):  # the root's position channels come first in these files
        values[:, axis] = values[0, axis] + factor * (values[:, axis] - values[0, axis])
    return BVH(clip.skeleton, clip.frame_time, values, clip.path)


def test_a_walk_that_travels_slower_than_the_clip_is_named(walk):
    """The early walk checkpoint's flaw: 0.66 m/s against the clip's 0.87 at full coverage (BENCHMARKS.md)."""
    row = plausibility(walk, [_slowed(walk, 0.75)])["samples"][0]
    assert row["clip_pace_m_s"] == pytest.approx(0.87, abs=0.03) and row["pace_m_s"] == pytest.approx(0.65, abs=0.03)
    assert row["verdict"].startswith("travels slower than the clip") and row["pace_distance_m_s"] > 0.15
    assert plausibility(walk, [_slowed(walk, 0.95)])["samples"][0]["verdict"] == "plausible"  # within 15 % of the pace
