"""Evaluation features (`sinmdm.eval.motion_features`) and `sinmdm eval` as a real process."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from sinmdm.eval.motion_features import (
    MIXAMO24_CONTACT_JOINTS,
    MIXAMO24_JOINTS,
    eval_features,
    evaluate_files,
    protocol_for,
    resolve_joints,
)
from sinmdm.runtime.animation import animation_from_bvh
from sinmdm.runtime.bvh import BVH, Skeleton, read_bvh, write_bvh
from sinmdm.runtime.errors import SinMDMError
from sinmdm.runtime.features import build_codec
from sinmdm.runtime.rotations import matrix_to_6d

from .conftest import DEMO_CLIP, real_clip, run_cli

METRIC_KEYS = ("coverage", "global_diversity", "local_diversity", "inter_diversity", "intra_diversity_diff")


def _write(path: Path, bvh: BVH, values: np.ndarray | None = None) -> Path:
    write_bvh(path, BVH(bvh.skeleton, bvh.frame_time, bvh.values if values is None else values))
    return path


def _chain_skeleton(names: tuple[str, ...]) -> Skeleton:
    count = len(names)
    return Skeleton(names, np.arange(-1, count - 1), np.ones((count, 3)), (("Xrotation", "Yrotation", "Zrotation"),) * count)


# --------------------------------------------------------------------------- protocol and features


def test_contains_matching_takes_the_first_joint_in_file_order():
    skeleton = _chain_skeleton(("ns:Hips", "ns:Spine", "ns:Spine1", "ns:Head", "ns:HeadTop_End", "ns:LeftHand", "ns:LeftHandThumb1"))
    found = resolve_joints(skeleton, ("Spine", "Spine1", "Head", "LeftHand", "Hips"), "contains")
    assert [skeleton.names[j] for j in found] == ["ns:Spine", "ns:Spine1", "ns:Head", "ns:LeftHand", "ns:Hips"]
    with pytest.raises(SinMDMError, match="clip.bvh: no joint matching 'LeftToe_End'"):
        resolve_joints(skeleton, ("Hips", "LeftToe_End"), "contains", "clip.bvh")
    with pytest.raises(SinMDMError, match="no joint named 'Spine'"):
        resolve_joints(skeleton, ("Spine",), "exact")


def test_default_preset_on_the_demo_clip():
    clip = read_bvh(DEMO_CLIP)
    protocol = protocol_for(clip)
    codec = build_codec(clip)
    assert len(protocol.joints) == 19 and protocol.contact_joints == ("LeftToe", "RightToe")
    assert protocol.contact_threshold == pytest.approx(codec.contact_speed / 30)
    features = eval_features(clip, protocol)
    assert features.shape == (360, 19 * 6 + 2) == (360, protocol.width)
    # Rotations are the codec's (the model's own representation), root translation left out.
    np.testing.assert_allclose(features[:, :114], codec.encode(clip)[:, :114], atol=1e-6)
    contacts = features[:, -2:]
    assert not contacts[0].any() and 0.2 < contacts.mean() < 0.9


def test_mixamo24_names_the_missing_joint():
    with pytest.raises(SinMDMError, match="stomper.bvh \\(mixamo24 preset\\): no joint matching 'LeftToeBase'"):
        protocol_for(read_bvh(DEMO_CLIP), "mixamo24")
    with pytest.raises(SinMDMError, match="unknown evaluation preset 'paper'"):
        protocol_for(read_bvh(DEMO_CLIP), "paper")


def test_sample_missing_a_joint_names_file_and_joint(tmp_path):
    clip = read_bvh(DEMO_CLIP)
    names = tuple("LeftFootRenamed" if n == "LeftFoot" else n for n in clip.skeleton.names)
    skeleton = Skeleton(names, clip.skeleton.parents, clip.skeleton.offsets, clip.skeleton.channels)
    write_bvh(tmp_path / "renamed.bvh", BVH(skeleton, clip.frame_time, clip.values))
    with pytest.raises(SinMDMError, match="renamed.bvh: no joint named 'LeftFoot'"):
        eval_features(read_bvh(tmp_path / "renamed.bvh"), protocol_for(clip))


def test_sample_in_other_units_scores_like_the_reference(tmp_path):
    # A peer may write metres for a reference in centimetres: same features.
    clip = read_bvh(DEMO_CLIP)
    position_columns = [c for c, name in enumerate(n for cs in clip.skeleton.channels for n in cs) if name.endswith("position")]
    values = clip.values.copy()
    values[:, position_columns] /= 100
    skeleton = Skeleton(clip.skeleton.names, clip.skeleton.parents, clip.skeleton.offsets / 100, clip.skeleton.channels)
    write_bvh(tmp_path / "metres.bvh", BVH(skeleton, clip.frame_time, values), precision=8)
    protocol = protocol_for(clip)
    ours, theirs = eval_features(clip, protocol), eval_features(read_bvh(tmp_path / "metres.bvh"), protocol)
    np.testing.assert_allclose(theirs[:, :-2], ours[:, :-2], atol=1e-6)
    assert np.mean(theirs[:, -2:] == ours[:, -2:]) > 0.99


def test_self_copy_and_excerpt_on_the_demo_clip(tmp_path):
    clip = read_bvh(DEMO_CLIP)
    excerpt = _write(tmp_path / "excerpt.bvh", clip, clip.values[:120])
    itself = evaluate_files(DEMO_CLIP, [DEMO_CLIP])
    assert itself["coverage"] == 100.0 and itself["local_diversity"] == pytest.approx(0, abs=1e-9)
    partial = evaluate_files(DEMO_CLIP, [excerpt])
    assert partial["coverage"] < 90 and partial["sample_frames"] == [120]


# --------------------------------------------------------------------------- real clips


@pytest.mark.realdata
def test_mixamo24_on_joe_reproduces_the_paper_protocol():
    clip = read_bvh(real_clip("Joe_Walk-In-Circle.bvh"))
    protocol = protocol_for(clip, "mixamo24")
    found = resolve_joints(clip.skeleton, protocol.joints, protocol.match)
    assert [clip.skeleton.names[j] for j in found] == [f"mixamorig7:{name}" for name in MIXAMO24_JOINTS]
    assert protocol.scale == 0.01 and protocol.contact_threshold == 0.018 and protocol.resample == "drop"
    features = eval_features(clip, protocol)
    assert features.shape == (math.ceil(753 / 2), 24 * 6 + 4) == (377, 148)
    # Frames are dropped, not interpolated: frame k is source frame 2k.
    animation = animation_from_bvh(clip)
    np.testing.assert_allclose(
        features[:, :144].reshape(377, 24, 6), matrix_to_6d(animation.rotations[::2][:, found]), atol=1e-12
    )
    contacts = features[:, 144:]
    assert set(np.unique(contacts)) == {0.0, 1.0} and not contacts[0].any()
    assert all(0.2 < share < 0.8 for share in contacts.mean(axis=0))
    assert len(MIXAMO24_CONTACT_JOINTS) == 4


@pytest.mark.realdata
def test_peer_output_on_the_reduced_skeleton_is_scored():
    # GANimator's reduced 24-joint skeleton: plain names, metres, 30 fps (declared 1 s).
    protocol = protocol_for(read_bvh(real_clip("Joe_Walk-In-Circle.bvh")), "mixamo24")
    features = eval_features(read_bvh(real_clip("Joe_traj-example.bvh")), protocol, source_fps=30)
    assert features.shape == (600, 148)
    assert 0.05 < features[:, 144:].mean() < 0.95  # metres recognised: contacts not all "planted"
    with pytest.raises(SinMDMError, match="Joe_traj-example.bvh: cannot drop frames from 1 to 30 fps"):
        eval_features(read_bvh(real_clip("Joe_traj-example.bvh")), protocol)


@pytest.mark.realdata
def test_joe_against_itself_and_a_reversed_copy(tmp_path):
    path = real_clip("Joe_Walk-In-Circle.bvh")
    clip = read_bvh(path)
    itself = evaluate_files(path, [path], preset="mixamo24")
    assert itself["coverage"] == 100.0
    assert itself["local_diversity"] == pytest.approx(0, abs=1e-9) and itself["global_diversity"] == pytest.approx(0, abs=1e-9)
    assert itself["feature_width"] == 148 and itself["reference_frames"] == 377

    reversed_copy = _write(tmp_path / "reversed.bvh", clip, clip.values[::-1])
    excerpt = _write(tmp_path / "excerpt.bvh", clip, clip.values[:250])
    scores = evaluate_files(path, [reversed_copy, excerpt], preset="mixamo24")
    assert scores["sample_frames"] == [377, 125]
    assert scores["global_diversity"] > 0.5 and scores["local_diversity"] > 0.5 and scores["inter_diversity"] > 0.1
    # A walk in a circle played backwards still matches every window within the
    # paper's threshold; a third of the circle does not cover the rest.
    assert evaluate_files(path, [excerpt], preset="mixamo24")["coverage"] < 95


@pytest.mark.realdata
def test_default_preset_on_the_crab(tmp_path):
    path = real_clip("Crabnew_Crab-dance-long.bvh")
    clip = read_bvh(path)
    protocol = protocol_for(clip)
    assert len(protocol.joints) == 56 and len(protocol.contact_joints) >= 2
    assert eval_features(clip, protocol).shape == (384, protocol.width)
    assert evaluate_files(path, [path])["coverage"] == 100.0

    rng = np.random.default_rng(0)
    chunks = np.array_split(clip.values, 8)
    shuffled = _write(tmp_path / "shuffled.bvh", clip, np.concatenate([chunks[i] for i in rng.permutation(8)]))
    reversed_copy = _write(tmp_path / "reversed.bvh", clip, clip.values[::-1])
    assert evaluate_files(path, [shuffled])["local_diversity"] > 0.05
    scores = evaluate_files(path, [reversed_copy])
    assert scores["coverage"] < 80 and scores["local_diversity"] > 0.5


# --------------------------------------------------------------------------- command line


def test_cli_json_with_two_lengths_and_no_torch(tmp_path, no_torch_env):
    clip = read_bvh(DEMO_CLIP)
    short = _write(tmp_path / "short.bvh", clip, clip.values[:200])
    reversed_copy = _write(tmp_path / "reversed.bvh", clip, clip.values[::-1])
    result = run_cli("sinmdm", "eval", str(DEMO_CLIP), str(short), str(reversed_copy), "--json", env=no_torch_env, check=True)
    scores = json.loads(result.stdout)
    assert all(isinstance(scores[key], float) for key in METRIC_KEYS)
    assert 0 <= scores["coverage"] <= 100 and scores["coverage"] > 1  # a percentage
    assert scores["samples"] == 2 and scores["sample_frames"] == [200, 360] and scores["reference_frames"] == 360
    assert scores["preset"] == "default" and scores["feature_width"] == 116


def test_cli_table(tmp_path):
    result = run_cli("sinmdm", "eval", str(DEMO_CLIP), str(DEMO_CLIP), "--seed", "3", check=True)
    for text in ("coverage", "global diversity", "local diversity", "inter diversity", "intra diversity diff", "94.30", "↑", "↓"):
        assert text in result.stdout


def test_cli_errors_are_one_line(tmp_path, no_torch_env):
    clip = read_bvh(DEMO_CLIP)
    malformed = tmp_path / "malformed.bvh"
    malformed.write_text(DEMO_CLIP.read_text().replace("MOTION", "MOTON"))
    too_short = _write(tmp_path / "short.bvh", clip, clip.values[:20])
    cases = {
        "missing.bvh": [str(DEMO_CLIP), str(tmp_path / "missing.bvh")],
        "malformed.bvh": [str(DEMO_CLIP), str(malformed)],
        "no samples": [str(DEMO_CLIP)],
        "unknown evaluation preset": [str(DEMO_CLIP), str(DEMO_CLIP), "--preset", "paper"],
        "short.bvh has 20 frames": [str(DEMO_CLIP), str(too_short)],
    }
    for expected, args in cases.items():
        result = run_cli("sinmdm", "eval", *args, env=no_torch_env)
        assert result.returncode == 2, (args, result.stderr)
        assert result.stderr.count("\n") == 1 and expected in result.stderr and "Traceback" not in result.stderr


@pytest.mark.realdata
def test_cli_refuses_a_sample_on_another_skeleton(no_torch_env):
    joe, xia = real_clip("Joe_Walk-In-Circle.bvh"), real_clip("Xia_normal.bvh")
    for preset, missing in (("mixamo24", "'LeftToe_End'"), ("default", "'mixamorig7:Hips'")):
        result = run_cli("sinmdm", "eval", str(joe), str(xia), "--preset", preset, env=no_torch_env)
        assert result.returncode == 2 and result.stdout == ""
        assert result.stderr.count("\n") == 1 and "Xia_normal.bvh" in result.stderr and missing in result.stderr
