"""BVH reader and writer: malformed and tricky corpora, round trips, real clips."""

from __future__ import annotations

import random
import re
import time
from pathlib import Path

import numpy as np
import pytest

from sinmdm.runtime.bvh import (
    BVH,
    MAX_DEPTH,
    MAX_JOINTS,
    Skeleton,
    format_bvh,
    parse_bvh,
    read_bvh,
    write_bvh,
)
from sinmdm.runtime.errors import BVHError, SinMDMError

DATA = Path(__file__).parent / "data"
BAD = DATA / "bvh_bad"
TRICKY = DATA / "bvh_tricky"
MOTIONS = Path(__file__).resolve().parents[2] / "shared" / "motions"

SIMPLE = """HIERARCHY
ROOT Hips
{
\tOFFSET 0 90 0
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
\tJOINT Spine
\t{
\t\tOFFSET 0 10 0
\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\tEnd Site
\t\t{
\t\t\tOFFSET 0 5 0
\t\t}
\t}
}
MOTION
Frames: 2
Frame Time: 0.033333
0 90 0 0 0 0 1 2 3
1 91 0 5 0 0 2 3 4
"""
SIMPLE_VALUES = np.array([[0, 90, 0, 0, 0, 0, 1, 2, 3], [1, 91, 0, 5, 0, 0, 2, 3, 4]], dtype=float)


def _readme_entries(folder: Path) -> dict[str, str]:
    entries = {}
    for line in (folder / "README.md").read_text(encoding="utf-8").splitlines():
        match = re.match(r"^`([^`]+\.bvh)`(.*)$", line)
        if match:
            entries[match.group(1)] = match.group(2)
    return entries


def _bad_cases() -> list[tuple[str, int, str]]:
    cases = []
    for name, rest in sorted(_readme_entries(BAD).items()):
        match = re.fullmatch(r" line (\d+): .*\[(.+)\]", rest)
        assert match, f"README entry for {name} is not `file` line N: what [fragment]"
        cases.append((name, int(match.group(1)), match.group(2)))
    return cases


def _assert_clean_error(error: BVHError, path: str) -> None:
    assert isinstance(error.line, int) and error.line >= 1
    assert "\n" not in str(error) and "\r" not in str(error)
    assert str(error).startswith(f"{path}:{error.line}: ")
    assert error.message and str(error).endswith(error.message)


# --------------------------------------------------------------------------- malformed corpus


def test_bad_corpus_matches_readme() -> None:
    files = {p.name for p in BAD.glob("*.bvh")}
    assert len(files) >= 24
    assert files == set(_readme_entries(BAD)), "every bad file needs exactly one README line"


@pytest.mark.parametrize("name, line, fragment", _bad_cases())
def test_bad_file_names_the_line(name: str, line: int, fragment: str) -> None:
    path = BAD / name
    with pytest.raises(BVHError) as info:
        read_bvh(path)
    _assert_clean_error(info.value, str(path))
    assert info.value.line == line, str(info.value)
    assert fragment in info.value.message


def _chain(depth: int) -> str:
    lines = ["HIERARCHY", "ROOT j0", "{", "OFFSET 0 0 0", "CHANNELS 3 Xrotation Yrotation Zrotation"]
    for j in range(1, depth):
        lines += [f"JOINT j{j}", "{", "OFFSET 0 1 0", "CHANNELS 0"]
    lines += ["}"] * depth + ["MOTION", "Frames: 1", "Frame Time: 0.1", "0 0 0"]
    return "\n".join(lines) + "\n"


def test_nesting_at_the_limit_parses() -> None:
    bvh = parse_bvh(_chain(MAX_DEPTH))
    assert bvh.skeleton.num_joints == MAX_DEPTH
    assert bvh.skeleton.parents[-1] == MAX_DEPTH - 2


def test_nesting_beyond_the_limit_is_a_clean_error() -> None:
    with pytest.raises(BVHError) as info:
        parse_bvh(_chain(MAX_DEPTH + 1), "deep.bvh")
    _assert_clean_error(info.value, "deep.bvh")
    # The joint that goes one level too deep: JOINT j{MAX_DEPTH} on line 6 + 4 * (MAX_DEPTH - 1).
    assert info.value.line == 6 + 4 * (MAX_DEPTH - 1)
    assert f"deeper than {MAX_DEPTH}" in info.value.message


def test_too_many_joints_is_a_clean_error() -> None:
    lines = ["HIERARCHY", "ROOT r", "{", "OFFSET 0 0 0"]
    for j in range(MAX_JOINTS):
        lines.append(f"JOINT j{j} {{ OFFSET 0 0 0 }}")
    lines += ["}", "MOTION", "Frames: 0", "Frame Time: 0.1"]
    with pytest.raises(BVHError) as info:
        parse_bvh("\n".join(lines), "many.bvh")
    assert info.value.line == 4 + MAX_JOINTS  # the JOINT line that would be joint number MAX_JOINTS + 1
    assert f"too many joints (the limit is {MAX_JOINTS})" in info.value.message


def test_mutated_files_raise_only_bvh_errors() -> None:
    """Truncations, dropped lines and flipped bytes: the reader either succeeds or
    raises a one-line BVHError naming a real line, never another exception."""
    rng = random.Random(1234)
    sources = [SIMPLE.encode(), (TRICKY / "several_roots.bvh").read_bytes(), (TRICKY / "names.bvh").read_bytes()]
    for trial in range(600):
        data = bytearray(rng.choice(sources))
        kind = trial % 4
        if kind == 0:
            del data[rng.randrange(len(data)):]
        elif kind == 1:
            lines = bytes(data).split(b"\n")
            del lines[rng.randrange(len(lines))]
            data = bytearray(b"\n".join(lines))
        elif kind == 2:
            for _ in range(rng.randint(1, 3)):
                data[rng.randrange(len(data))] = rng.choice(b"{}0.-x \n\t\rNaE:")
        else:
            position = rng.randrange(len(data))
            data[position:position] = rng.choice([b"}", b"{", b" 1", b"\n", b"JOINT", b"End Site", b"nan"])
        try:
            parse_bvh(bytes(data), "fuzz.bvh")
        except BVHError as error:
            _assert_clean_error(error, "fuzz.bvh")
            assert error.line <= bytes(data).count(b"\n") + bytes(data).count(b"\r") + 1


def test_unreadable_paths_raise_sinmdm_error(tmp_path: Path) -> None:
    for path in (tmp_path / "missing.bvh", tmp_path):
        with pytest.raises(SinMDMError, match="^cannot read "):
            read_bvh(path)


def test_parse_errors_use_the_given_path() -> None:
    with pytest.raises(BVHError, match=r"^<string>:1: file is empty$"):
        parse_bvh("")
    with pytest.raises(BVHError, match=r"^clip\.bvh:2: expected a name after ROOT$"):
        parse_bvh("HIERARCHY\nROOT\n", "clip.bvh")


# --------------------------------------------------------------------------- tricky-valid corpus


def test_tricky_corpus_matches_readme() -> None:
    assert {p.name for p in TRICKY.glob("*.bvh")} == set(_readme_entries(TRICKY))


SIMPLE_LIKE = ["cr_only.bvh", "crlf.bvh", "tabs_spaces_blank_lines.bvh", "utf8_bom.bvh", "utf16_bom.bvh",
               "header_order_swapped.bvh"]


@pytest.mark.parametrize("name", SIMPLE_LIKE)
def test_tricky_spelling_gives_the_simple_file(name: str) -> None:
    assert read_bvh(TRICKY / name) == parse_bvh(SIMPLE)


def test_line_ends_and_encodings_in_memory() -> None:
    expected = parse_bvh(SIMPLE)
    assert expected.path is None
    assert np.array_equal(expected.values, SIMPLE_VALUES)
    for variant in (SIMPLE.replace("\n", "\r\n"), SIMPLE.replace("\n", "\r"), "\n\n" + SIMPLE + "\n \n\t\n",
                    SIMPLE.replace("\t", "    "), SIMPLE.lower().replace("hips", "Hips").replace("spine", "Spine")):
        assert parse_bvh(variant) == expected
        assert parse_bvh(variant.encode("utf-8")) == expected


def test_several_roots() -> None:
    bvh = read_bvh(TRICKY / "several_roots.bvh")
    skeleton = bvh.skeleton
    assert skeleton.names == ("Body", "Head", "Prop", "Lid", "Ball")
    assert skeleton.parents.tolist() == [-1, 0, -1, 2, -1]
    assert skeleton.roots == [0, 2, 4]
    assert skeleton.channels[2] == ()  # no CHANNELS line at all
    assert skeleton.channels[3] == ("Xrotation",)
    assert skeleton.position_channels(4) == ("X", "Y", "Z") and skeleton.rotation_order(4) == ""
    assert skeleton.channel_starts.tolist() == [0, 6, 9, 9, 10]
    assert bvh.values[:, 9].tolist() == [10, 20]
    assert bvh.frame_time == 0.04 and bvh.fps == pytest.approx(25)


def test_dummy_root() -> None:
    skeleton = read_bvh(TRICKY / "dummy_root.bvh").skeleton
    assert skeleton.names[:2] == ("Armature", "Hips")
    assert skeleton.channels[0] == () and skeleton.rotation_order(0) == ""
    assert skeleton.parents.tolist() == [-1, 0, 1, 1]
    assert [skeleton.rotation_order(j) for j in (1, 2, 3)] == ["ZYX"] * 3
    assert skeleton.position_channels(1) == ("X", "Y", "Z")
    assert skeleton.children(1) == [2, 3] and skeleton.children(2) == []
    assert skeleton.num_channels == 12


def test_zxy_order_and_six_channels() -> None:
    zxy = read_bvh(TRICKY / "zxy_order.bvh")
    assert [zxy.skeleton.rotation_order(j) for j in range(2)] == ["ZXY", "ZXY"]
    assert zxy.frame_time == 0.008333
    six = read_bvh(TRICKY / "six_channels_everywhere.bvh").skeleton
    assert all(len(c) == 6 for c in six.channels)
    assert all(six.position_channels(j) == ("X", "Y", "Z") for j in range(3))


def test_wrapped_values() -> None:
    bvh = read_bvh(TRICKY / "wrapped_values.bvh")
    assert bvh.values.shape == (3, 9)
    assert bvh.values[2].tolist() == [2, 92, 0, 6, 0, 0, 3, 4, 5]


def test_names() -> None:
    skeleton = read_bvh(TRICKY / "names.bvh").skeleton
    assert skeleton.names == ("mixamorig:Hips", "Left Arm", "Épaule_gauche", "頭")
    assert skeleton.index("Left Arm") == 1
    assert skeleton.parents.tolist() == [-1, 0, 1, 0]
    assert read_bvh(TRICKY / "latin1_names.bvh").skeleton.names == ("Hüfte", "Épaule")


def test_end_site_without_offset() -> None:
    skeleton = read_bvh(TRICKY / "end_site_without_offset.bvh").skeleton
    assert len(skeleton.end_sites) == 2
    (first_parent, first_offset), (second_parent, second_offset) = skeleton.end_sites
    assert (first_parent, first_offset) == (1, None)
    assert second_parent == 0 and second_offset.tolist() == [0, -5, 0]


def test_channels_zero_in_the_middle() -> None:
    bvh = read_bvh(TRICKY / "channels_zero_middle.bvh")
    assert bvh.skeleton.channels[1] == ()
    assert bvh.skeleton.channel_starts.tolist() == [0, 6, 6]
    assert bvh.values[1, 6:].tolist() == [4, 5, 6]


def test_position_channel_on_a_child() -> None:
    skeleton = read_bvh(TRICKY / "position_on_child.bvh").skeleton
    assert skeleton.channels[1] == ("Zrotation", "Yposition", "Xrotation", "Yrotation")
    assert skeleton.rotation_order(1) == "ZXY" and skeleton.position_channels(1) == ("Y",)
    assert skeleton.rotation_order(0) == "" and skeleton.rotation_order(2) == "X"


def test_braces_on_name_lines_and_zero_frames() -> None:
    compact = read_bvh(TRICKY / "braces_on_name_line.bvh")
    assert compact.skeleton.names == ("Hips", "Spine") and compact.skeleton.end_sites[0][0] == 1
    assert read_bvh(TRICKY / "zero_frames.bvh").values.shape == (0, 9)


@pytest.mark.parametrize("name", sorted(p.name for p in TRICKY.glob("*.bvh")))
def test_tricky_files_round_trip(name: str, tmp_path: Path) -> None:
    bvh = read_bvh(TRICKY / name)
    assert bvh.path == str(TRICKY / name)
    write_bvh(tmp_path / name, bvh, unwrap=False)
    again = read_bvh(tmp_path / name)
    assert again == bvh


# --------------------------------------------------------------------------- API


def test_skeleton_helpers() -> None:
    skeleton = parse_bvh(SIMPLE).skeleton
    assert skeleton.num_joints == 2 and skeleton.num_channels == 9
    assert skeleton.channel_starts.dtype == np.int64 and skeleton.channel_starts.tolist() == [0, 6]
    assert skeleton.parents.dtype == np.int64 and skeleton.offsets.dtype == np.float64
    assert skeleton.offsets.tolist() == [[0, 90, 0], [0, 10, 0]]
    assert skeleton.index("Spine") == 1
    with pytest.raises(SinMDMError, match="unknown joint 'Head'"):
        skeleton.index("Head")
    other = parse_bvh(SIMPLE.replace("OFFSET 0 10 0", "OFFSET 0 12 0")).skeleton
    assert skeleton.same_hierarchy(other) and skeleton != other
    assert not skeleton.same_hierarchy(parse_bvh(SIMPLE.replace("Spine", "Chest")).skeleton)


def test_arrays_are_read_only() -> None:
    bvh = parse_bvh(SIMPLE)
    with pytest.raises(ValueError):
        bvh.values[0, 0] = 1.0
    with pytest.raises(ValueError):
        bvh.skeleton.offsets[0, 0] = 1.0


def test_skeleton_rejects_inconsistent_data() -> None:
    good = dict(names=("a", "b", "c"), parents=np.array([-1, 0, 0]), offsets=np.zeros((3, 3)),
                channels=((), (), ()), end_sites=())
    Skeleton(**good)
    for change in (dict(parents=np.array([-1, 2, 0])), dict(names=("a", "a", "c")), dict(offsets=np.zeros((2, 3))),
                   dict(channels=(("Wrotation",), (), ())), dict(names=("a", "b\nc", "d")),
                   dict(end_sites=((5, None),))):
        with pytest.raises(ValueError):
            Skeleton(**{**good, **change})
    skeleton = Skeleton(**good)
    with pytest.raises(ValueError):
        BVH(skeleton, 0.0, np.zeros((1, 0)))
    with pytest.raises(ValueError):
        BVH(skeleton, 0.1, np.zeros((1, 3)))


# --------------------------------------------------------------------------- writer


def test_format_layout() -> None:
    text = format_bvh(parse_bvh(SIMPLE))
    assert "\r" not in text and text.endswith("\n")
    lines = text.split("\n")
    assert lines[:4] == ["HIERARCHY", "ROOT Hips", "{", "\tOFFSET 0 90 0"]
    assert "\t\tCHANNELS 3 Zrotation Xrotation Yrotation" in lines
    assert "\t\tEnd Site" in lines and "\t\t\tOFFSET 0 5 0" in lines
    assert "Frame Time: 0.033333" in lines and "Frames: 2" in lines
    assert lines[-3:] == ["0.000000 90.000000 0.000000 0.000000 0.000000 0.000000 1.000000 2.000000 3.000000",
                          "1.000000 91.000000 0.000000 5.000000 0.000000 0.000000 2.000000 3.000000 4.000000", ""]


def test_frame_time_round_trips_exactly() -> None:
    bvh = parse_bvh(SIMPLE)
    for frame_time in (1 / 60, 1 / 120, 1 / 30, 0.5, 1e-4, 10.0):
        clip = BVH(bvh.skeleton, frame_time, bvh.values)
        assert parse_bvh(format_bvh(clip)).frame_time == frame_time


def test_precision_and_negative_zero() -> None:
    bvh = parse_bvh(SIMPLE)
    values = np.full_like(bvh.values, -1e-9)
    values[0, 0] = 1.23456789
    text = format_bvh(BVH(bvh.skeleton, bvh.frame_time, values), precision=3)
    assert text.split("\n")[-3].split()[:2] == ["1.235", "0.000"]
    assert "-0.000" not in text


def test_unwrap_rotations_only() -> None:
    skeleton = parse_bvh(SIMPLE).skeleton
    frames = 50
    values = np.zeros((frames, 9))
    angle = np.linspace(0, 720, frames)
    wrapped = (angle + 180) % 360 - 180
    values[:, 3] = wrapped  # Hips Zrotation, wraps at +-180
    values[:, 0] = wrapped  # Hips Xposition: same numbers, but positions are never unwrapped
    clip = BVH(skeleton, 1 / 30, values)
    out = parse_bvh(format_bvh(clip)).values
    assert np.allclose(out[:, 3], angle - 0.0, atol=1e-6)
    assert np.abs(np.diff(out[:, 3])).max() < 180
    assert np.allclose(out[:, 0], wrapped, atol=1e-6)
    kept = parse_bvh(format_bvh(clip, unwrap=False)).values
    assert np.allclose(kept, values, atol=1e-6)


def test_write_bvh_is_atomic_and_complete(tmp_path: Path) -> None:
    bvh = parse_bvh(SIMPLE)
    target = tmp_path / "out.bvh"
    write_bvh(target, bvh, precision=4)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.bvh"]
    assert target.read_text() == format_bvh(bvh, precision=4)
    assert read_bvh(target) == bvh


def test_writer_keeps_end_site_order_and_several_roots() -> None:
    text = """HIERARCHY
ROOT A
{
  OFFSET 0 0 0
  End Site
  {
    OFFSET 1 1 1
  }
  JOINT B
  {
    OFFSET 0 1 0
    CHANNELS 1 Yrotation
  }
  End Site
  {
  }
}
ROOT C
{
  OFFSET 2 0 0
  CHANNELS 2 Xposition Zrotation
}
MOTION
Frames: 1
Frame Time: 0.1
370 1 -400
"""
    bvh = parse_bvh(text)
    assert [p for p, _ in bvh.skeleton.end_sites] == [0, 0]
    again = parse_bvh(format_bvh(bvh))
    assert again.skeleton == bvh.skeleton
    assert np.array_equal(again.values, bvh.values)


# --------------------------------------------------------------------------- real clips

needs_motions = pytest.mark.skipif(not MOTIONS.is_dir(), reason="../shared/motions is absent")
REAL_CLIPS = sorted(p.name for p in MOTIONS.glob("*.bvh")) if MOTIONS.is_dir() else []


@pytest.mark.realdata
@needs_motions
def test_all_eight_real_clips_present() -> None:
    assert len(REAL_CLIPS) == 8


@pytest.mark.realdata
@needs_motions
@pytest.mark.parametrize("name", REAL_CLIPS)
def test_real_clip_round_trips(name: str) -> None:
    bvh = read_bvh(MOTIONS / name)
    skeleton = bvh.skeleton
    exact = parse_bvh(format_bvh(bvh, unwrap=False))
    assert exact.skeleton == skeleton and exact.frame_time == bvh.frame_time
    assert np.abs(exact.values - bvh.values).max() <= 1e-6

    smooth = parse_bvh(format_bvh(bvh)).values
    is_rotation = np.array([c.endswith("rotation") for cs in skeleton.channels for c in cs])
    assert np.abs(smooth[:, ~is_rotation] - bvh.values[:, ~is_rotation]).max() <= 1e-6
    difference = smooth[:, is_rotation] - bvh.values[:, is_rotation]
    assert np.abs(difference - 360 * np.round(difference / 360)).max() <= 1e-6  # same rotations
    assert np.abs(np.diff(smooth[:, is_rotation], axis=0)).max(initial=0) <= 180


@pytest.mark.realdata
@needs_motions
def test_real_clip_facts() -> None:
    walk = read_bvh(MOTIONS / "Joe_Walk-In-Circle.bvh")
    assert (walk.skeleton.num_joints, walk.frames, walk.frame_time) == (65, 753, 0.016667)
    assert all(name.startswith("mixamorig") and ":" in name for name in walk.skeleton.names)
    assert len(walk.skeleton.channels[0]) == 6 and all(len(c) == 3 for c in walk.skeleton.channels[1:])

    crab = read_bvh(MOTIONS / "Crabnew_Crab-dance-long.bvh")
    assert (crab.skeleton.num_joints, crab.frames, crab.frame_time) == (56, 384, 0.033333)

    elephant = read_bvh(MOTIONS / "Elephant_idle1.bvh")
    assert (elephant.skeleton.num_joints, elephant.frames) == (40, 201)
    assert all(len(c) == 6 for c in elephant.skeleton.channels)

    xia = read_bvh(MOTIONS / "Xia_normal.bvh")
    assert (xia.skeleton.num_joints, xia.frames, xia.frame_time) == (31, 360, 0.008333)
    assert {xia.skeleton.rotation_order(j) for j in range(31)} == {"ZYX"}

    keys = read_bvh(MOTIONS / "Joe_Baseball-Milling-Idle-edited-keyframes.bvh")
    assert (keys.skeleton.num_joints, keys.frames, keys.frame_time) == (24, 21, 1.0)


@pytest.mark.realdata
@needs_motions
def test_largest_clip_is_fast() -> None:
    path = MOTIONS / "Joe_Baseball-Milling-Idle.bvh"
    start = time.perf_counter()
    bvh = read_bvh(path)
    parse_seconds = time.perf_counter() - start
    start = time.perf_counter()
    text = format_bvh(bvh)
    format_seconds = time.perf_counter() - start
    assert bvh.values.shape == (1264, 198) and len(text) > 2_000_000
    assert parse_seconds < 1.0, f"parse took {parse_seconds:.2f} s"
    assert format_seconds < 1.5, f"format took {format_seconds:.2f} s"
