"""Applications at inference time, on real models: composition keeps what it must,
generates the rest; trajectory control follows the path; harmonization keeps the
reference's low frequencies and moves toward the model's motion."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sinmdm.eval.metrics import evaluate
from sinmdm.eval.motion_features import eval_features, protocol_for
from sinmdm.runtime import SamplingOptions, load_model, read_bvh
from sinmdm.runtime.animation import animation_from_bvh, global_positions
from sinmdm.runtime.applications import (
    load_reference, load_trajectory, plan_control, plan_expand, plan_harmonize, plan_inbetween, plan_keyframes, run_plan,
)
from sinmdm.runtime.bvh import BVH, write_bvh
from sinmdm.runtime.errors import SinMDMError
from sinmdm.runtime.features import skeleton_size
from sinmdm.runtime.masks import body_halves, frame_ramp
from sinmdm.runtime.sampler import low_pass

from .conftest import DEMO_CLIP, real_clip, run_cli

REQUEST = SamplingOptions(count=2, seed=0, steps=10)


def positions(clip: BVH) -> np.ndarray:
    return global_positions(animation_from_bvh(clip))


def local_positions(clip: BVH) -> np.ndarray:
    p = positions(clip)
    return p - p[:, :1]


@pytest.fixture(scope="module")
def tiny(tiny_model):
    return load_model(tiny_model)


@pytest.fixture(scope="module")
def reference(tiny):
    return load_reference(tiny, DEMO_CLIP)


def test_frame_ramp_is_inside_the_kept_range():
    w = frame_ramp(20, [(0, 8), (12, 20)], 3)
    assert list(w[:5]) == [1] * 5 and list(w[5:8]) == [0.75, 0.5, 0.25] and w[8:12].sum() == 0
    assert list(w[12:15]) == [0.25, 0.5, 0.75] and w[-1] == 1


def test_inbetween_keeps_both_ends_and_lands_on_the_path(tiny, reference):
    plan = plan_inbetween(tiny, reference)
    result = run_plan(tiny, plan, REQUEST)
    ref_clip = tiny.codec.decode_bvh(reference.features, reference.start)
    size = skeleton_size(ref_clip.skeleton)
    head, tail = 90 - 10, 270 + 10  # 25 % of 360 frames, minus the 10-frame ramps
    for clip in result.clips:
        assert clip.frames == 360
        err_head = np.abs(positions(clip)[:head] - positions(ref_clip)[:head]).max() / size
        err_tail = np.abs(local_positions(clip)[tail:] - local_positions(ref_clip)[tail:]).max() / size
        err_landing = np.abs(positions(clip)[tail:] - positions(ref_clip)[tail:]).max() / size
        assert err_head < 1e-4 and err_tail < 1e-4 and err_landing < 0.02
    a, b = (positions(c)[100:260] for c in result.clips)
    assert np.abs(a - b).max() > 1e-3 * size  # the generated middle differs across seeds


def test_expand_adds_15_percent_each_side(tiny, reference):
    plan = plan_expand(tiny, reference)
    result = run_plan(tiny, plan, REQUEST)
    assert plan.frames == 54 + 360 + 54
    ref_local = local_positions(tiny.codec.decode_bvh(reference.features, reference.start))
    for clip in result.clips:
        kept = local_positions(clip)[54 + 6 : 54 + 360 - 6]
        assert np.abs(kept - ref_local[6:-6]).max() / skeleton_size(clip.skeleton) < 1e-4


def test_keyframes_hold_the_key_poses(tiny, reference):
    keys = [0, 60, 200, 359]
    result = run_plan(tiny, plan_keyframes(tiny, reference, keys), REQUEST)
    ref_local = local_positions(tiny.codec.decode_bvh(reference.features, reference.start))
    for clip in result.clips:
        assert np.abs(local_positions(clip)[keys] - ref_local[keys]).max() / skeleton_size(clip.skeleton) < 1e-4


def test_upper_and_lower_body_from_the_hierarchy(tiny):
    upper, lower = body_halves(tiny.codec)
    assert lower == {"Hips", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToe", "RightUpLeg", "RightLeg", "RightFoot", "RightToe"}
    assert {"Spine", "Head", "LeftHand"} <= upper and not upper & lower


@pytest.mark.parametrize("joints", ["upper-body", "lower-body", "LeftArm,LeftForeArm"])
def test_joint_control_keeps_the_joints(tiny, reference, joints):
    plan = plan_control(tiny, reference, joints=joints)
    result = run_plan(tiny, plan, REQUEST)
    kept_rows = np.flatnonzero(plan.guide.keep[:, 0])
    for features in result.features:
        np.testing.assert_allclose(features[:, kept_rows], reference.features[:, kept_rows], atol=1e-5)
    free = np.setdiff1d(np.arange(tiny.features), kept_rows)
    assert np.abs(result.features[0][:, free] - result.features[1][:, free]).max() > 1e-3


def test_subtree_control(tiny, reference):
    plan = plan_control(tiny, reference, subtree="LeftArm")
    kept = {b.joint for b in tiny.codec.layout.blocks if plan.guide.keep[b.start, 0] == 1}
    assert kept == {"LeftArm", "LeftForeArm", "LeftHand"}


@pytest.mark.realdata
def test_trajectory_control_follows_a_path_from_another_skeleton():
    model = load_model()  # the bundled demo model (stomper skeleton, cm)
    path = real_clip("Joe_traj-example.bvh")  # 24-joint Mixamo skeleton in metres, frame time written wrong
    reference = load_trajectory(model, path, source_fps=30)
    plan = plan_control(model, reference, trajectory=True, frames=300)
    result = run_plan(model, plan, REQUEST)
    root_path = read_bvh(path).values[:300, [0, 2]]
    want = root_path - root_path[0]
    for clip in result.clips:
        got = positions(clip)[:, 0, [0, 2]] * model.codec.scale
        assert np.abs((got - got[0]) - want).max() < 0.01  # metres


def test_whole_clip_harmonization_keeps_low_frequencies(tiny, reference):
    result = run_plan(tiny, plan_harmonize(tiny, reference), REQUEST)
    ref = reference.features.T
    for features in result.features:
        out = features.T
        low_err = np.abs(low_pass(out, 4) - low_pass(ref, 4)).mean()
        full_err = np.abs(out - ref).mean()
        assert low_err < full_err


def test_partial_harmonization_keeps_the_base_outside(tiny, reference):
    base = run_plan(tiny, plan_inbetween(tiny, reference), SamplingOptions(steps=5)).features[0]
    plan = plan_harmonize(tiny, reference, frame_range=(100, 200), base=base, border=10)
    assert plan.guide.keep[:, :90].min() == 1 and plan.guide.keep[:, 210:].min() == 1
    assert plan.guide.harmonize[:, 100:200].min() == 1
    result = run_plan(tiny, plan, REQUEST)
    np.testing.assert_allclose(result.features[0][:90], base[:90], atol=1e-5)


def test_reference_on_another_skeleton_is_refused(tiny):
    with pytest.raises(SinMDMError, match="reference .* joints"):
        load_reference(tiny, real_clip("Xia_normal.bvh"))


def test_commands_write_bvh_files(tiny_model, tmp_path):
    for command, extra in [("inbetween", []), ("expand", []), ("keyframes", ["--every", "45"]),
                           ("control", ["--joints", "upper-body"]), ("harmonize", []),
                           ("harmonize", ["--frames", "100:200", "--force"])]:
        result = run_cli("sinmdm-run", command, str(tiny_model), "--ref", str(DEMO_CLIP), "--steps", "4",
                         "--out", str(tmp_path), "--json", *extra, check=True)
        files = json.loads(result.stdout)["files"]
        assert len(files) == 1 and read_bvh(files[0]).skeleton.names == read_bvh(DEMO_CLIP).skeleton.names


def test_command_with_mismatched_reference_exits_2(tiny_model, tmp_path):
    result = run_cli("sinmdm-run", "inbetween", str(tiny_model), "--ref", str(real_clip("Xia_normal.bvh")),
                     "--out", str(tmp_path))
    assert result.returncode == 2 and "reference" in result.stderr and "Traceback" not in result.stderr
    assert not any(tmp_path.iterdir())


def test_style_transfer_moves_toward_the_model_and_keeps_the_content(tmp_path):
    """Harmonize a jittery (unseen) version of the demo clip with the bundled demo model:
    the result is much closer to the model's motion (local diversity against the
    training clip, the paper's metric) and keeps the reference's low frequencies."""
    model = load_model()
    clip = read_bvh(DEMO_CLIP)
    values = clip.values.copy()
    t = np.arange(len(values)) / 30
    values[:, 3:] += 12 * np.sin(2 * np.pi * 9 * t)[:, None] * np.cos(np.arange(values.shape[1] - 3))[None]
    jittery = tmp_path / "jittery.bvh"
    write_bvh(jittery, BVH(clip.skeleton, clip.frame_time, values))
    reference = load_reference(model, jittery)
    protocol = protocol_for(clip)
    training = eval_features(clip, protocol)
    before = evaluate(training, [eval_features(read_bvh(jittery), protocol)])["local_diversity"]
    result = run_plan(model, plan_harmonize(model, reference), SamplingOptions(count=2, seed=0, steps=20))
    for styled, features in zip(result.clips, result.features):
        after = evaluate(training, [eval_features(styled, protocol)])["local_diversity"]
        assert after < 0.6 * before
        low_error = np.abs(low_pass(features.T, 8) - low_pass(reference.features.T, 8)).mean()
        assert low_error < 0.05
