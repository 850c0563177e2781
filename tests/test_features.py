"""Motion features: encode/decode round trips, layout, units, contacts, resampling."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sinmdm.runtime.animation import animation_from_bvh, global_positions, nominal_fps
from sinmdm.runtime.bvh import read_bvh
from sinmdm.runtime.errors import SinMDMError
from sinmdm.runtime.features import MotionCodec, build_codec, skeleton_size, unit_scale

from .conftest import DEMO_CLIP, REAL_CLIPS, WRONG_FRAME_TIME, real_clip


def round_trip_error(path, **options) -> tuple[float, MotionCodec]:
    bvh = read_bvh(path)
    source_fps = options.pop("source_fps", None)
    fps = source_fps or nominal_fps(bvh.frame_time)
    codec = build_codec(bvh, fps=fps, source_fps=source_fps, **options)
    features = codec.encode(bvh, source_fps=source_fps)
    out = codec.decode_bvh(features, codec.start_position(bvh, source_fps=source_fps))
    expected = global_positions(animation_from_bvh(bvh))
    got = global_positions(animation_from_bvh(out))
    assert got.shape == expected.shape
    return float(np.abs(expected - got).max() / skeleton_size(bvh.skeleton)), codec


def test_demo_clip_round_trip():
    error, codec = round_trip_error(DEMO_CLIP)
    assert error < 1e-4
    assert codec.scale == 0.01  # authored in cm
    names = [codec.skeleton.names[j] for j in codec.contact_joints]
    assert names == ["LeftToe", "RightToe"]


@pytest.mark.realdata
@pytest.mark.parametrize("path", REAL_CLIPS, ids=lambda p: p.name)
def test_real_clips_round_trip(path):
    error, codec = round_trip_error(path, source_fps=WRONG_FRAME_TIME.get(path.name))
    assert error < 1e-4, f"{path.name}: {error}"


def test_layout_names_every_channel():
    codec = build_codec(read_bvh(DEMO_CLIP))
    layout = codec.layout
    covered = np.zeros(layout.width, dtype=int)
    for block in layout.blocks:
        covered[block.start : block.stop] += 1
        assert block.stop - block.start == len(block.components)
    assert (covered == 1).all()
    assert layout.joints("root") == ["Hips"]
    assert len(layout.indices(("rotation",))) == 6 * 19
    assert list(layout.indices(("root",))) == [layout.width - 3, layout.width - 2, layout.width - 1]
    assert len(layout.indices(joints={"LeftArm", "LeftForeArm"})) == 12


def test_codec_serialises_to_json_and_back():
    codec = build_codec(read_bvh(DEMO_CLIP))
    data = json.loads(json.dumps(codec.to_dict()))
    again = MotionCodec.from_dict(data)
    assert again.layout == codec.layout
    bvh = read_bvh(DEMO_CLIP)
    np.testing.assert_array_equal(again.encode(bvh), codec.encode(bvh))


def test_root_is_velocity_and_height():
    bvh = read_bvh(DEMO_CLIP)
    codec = build_codec(bvh)
    features = codec.encode(bvh)
    root = features[:, codec.layout.indices(("root",))]
    hips = bvh.values[:, :3] * 0.01
    np.testing.assert_allclose(root[1:, 0], np.diff(hips[:, 0]), atol=1e-6)
    np.testing.assert_allclose(root[:, 1], hips[:, 1], atol=1e-6)
    np.testing.assert_allclose(root[0], root[1] * [1, 0, 1] + [0, hips[0, 1], 0], atol=1e-6)


def test_resampling_uses_slerp_not_dropping():
    bvh = read_bvh(DEMO_CLIP)
    codec = build_codec(bvh, fps=24.0)
    features = codec.encode(bvh)
    assert features.shape[0] == 288  # (360 - 1) * 24/30 + 1, floored
    # decoded at 24 fps, joint positions stay close to the 30 fps original at shared times
    decoded = global_positions(codec.decode(features, codec.start_position(bvh)))
    original = global_positions(animation_from_bvh(bvh))
    np.testing.assert_allclose(decoded[::4], original[::5], atol=1e-3 * skeleton_size(bvh.skeleton))


def test_units():
    skeleton = read_bvh(DEMO_CLIP).skeleton
    assert unit_scale(skeleton, "auto") == 0.01
    assert unit_scale(skeleton, "m") == 1.0
    assert unit_scale(skeleton, "0.5") == 0.5
    with pytest.raises(SinMDMError, match="unknown units"):
        unit_scale(skeleton, "furlongs")


def test_contacts_overridable_by_name():
    bvh = read_bvh(DEMO_CLIP)
    codec = build_codec(bvh, contacts=["LeftFoot", "RightFoot"])
    assert [codec.skeleton.names[j] for j in codec.contact_joints] == ["LeftFoot", "RightFoot"]
    with pytest.raises(SinMDMError, match="Nope"):
        build_codec(bvh, contacts=["Nope"])


def test_other_skeleton_is_refused_naming_the_joint():
    bvh = read_bvh(DEMO_CLIP)
    codec = build_codec(bvh)
    other = read_bvh(real_clip("Xia_normal.bvh"))
    with pytest.raises(SinMDMError, match="joints"):
        codec.encode(other)


@pytest.mark.realdata
@pytest.mark.parametrize(
    "name, expected",
    [
        ("Crabnew_Crab-dance-long.bvh", 6),  # six leg tips
        ("Joe_Walk-In-Circle.bvh", None),
        ("Elephant_idle1.bvh", None),
    ],
)
def test_contacts_detected_on_real_skeletons(name, expected):
    bvh = read_bvh(real_clip(name))
    codec = build_codec(bvh)
    names = [codec.skeleton.names[j] for j in codec.contact_joints]
    if expected is not None:
        assert len(names) == expected
        assert all("Leg" in n or "leg" in n for n in names)
    if name.startswith("Joe"):
        assert {"mixamorig7:LeftToeBase", "mixamorig7:RightToeBase"} <= set(names)
        assert not any("Hand" in n or "Arm" in n for n in names)
    if name.startswith("Elephant"):
        assert any("Foot" in n for n in names)


@pytest.mark.realdata
def test_per_joint_translations_kept_only_where_they_vary():
    codec = build_codec(read_bvh(real_clip("Elephant_idle1.bvh")))
    assert 0 < len(codec.translation_joints) < codec.skeleton.num_joints - 1
    assert len(codec.layout.indices(("translation",))) == 3 * len(codec.translation_joints)
