"""Bounds on what a BVH input may be: frame counts, frame times, values, units, source
frame rates and the file itself. Each refusal is one error naming the file (and line),
raised before any heavy work."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

from sinmdm.runtime.bvh import BVHError, read_bvh
from sinmdm.runtime.errors import OptionError, SinMDMError
from sinmdm.runtime.features import build_codec, unit_scale

from .conftest import DEMO_CLIP, run_cli
from .test_bvh import SIMPLE

HEADER = SIMPLE[: SIMPLE.index("Frames:")]
FRAMES_LINE = HEADER.count("\n") + 1
FRAME_TIME_LINE = FRAMES_LINE + 1


def clip_text(frames: int, frame_time: str = "0.033333", value: str = "1") -> str:
    rows = [" ".join([value] + ["0"] * 8)] * frames
    return HEADER + f"Frames: {frames}\nFrame Time: {frame_time}\n" + "".join(row + "\n" for row in rows)


def write_clip(tmp_path: Path, text: str, name: str = "clip.bvh") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def assert_one_line_exit_2(result, path: Path) -> None:
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2, result.stderr
    assert len(lines) == 1 and str(path) in lines[0] and "Traceback" not in result.stderr


def test_a_clip_without_frames_is_refused_by_the_codec_naming_the_file(tmp_path):
    path = write_clip(tmp_path, clip_text(0))
    clip = read_bvh(path)  # a clip with no frames is a valid file...
    with pytest.raises(SinMDMError, match=f"^{path} has no frames"):
        build_codec(clip)  # ...that cannot be used
    codec = build_codec(read_bvh(DEMO_CLIP))
    empty = read_bvh(write_clip(tmp_path, _without_frames(DEMO_CLIP), "demo0.bvh"))
    with pytest.raises(SinMDMError, match="has no frames"):
        codec.encode(empty)
    assert_one_line_exit_2(run_cli("sinmdm-run", "inspect", str(path)), path)


def _without_frames(path: Path) -> str:
    text = path.read_text()
    head = text[: text.index("Frames:")]
    return head + "Frames: 0\nFrame Time: 0.033333\n"


@pytest.mark.parametrize("frame_time", ["1e-320", "0.00001", "1e308", "100", "10.5"])
def test_frame_time_outside_the_bounds_names_its_line(tmp_path, frame_time):
    path = write_clip(tmp_path, clip_text(3, frame_time))
    with pytest.raises(BVHError) as info:
        read_bvh(path)
    assert info.value.path == str(path) and info.value.line == FRAME_TIME_LINE
    assert "outside 0.0001 .. 10 s" in info.value.message


def test_a_long_frame_time_that_resamples_past_an_hour_names_source_fps(tmp_path):
    path = write_clip(tmp_path, clip_text(400, "10"))  # 4,000 s at 10 s a frame
    clip = read_bvh(path)
    started = time.perf_counter()
    with pytest.raises(OptionError) as info:
        build_codec(clip)
    assert time.perf_counter() - started < 1.0
    assert info.value.option == "source_fps" and str(path) in info.value.message
    assert build_codec(clip, source_fps=30).fps == 30.0  # the real rate makes it usable
    result = run_cli("sinmdm-run", "inspect", str(path))
    assert_one_line_exit_2(result, path)
    assert "source-fps" in result.stderr or "source_fps" in result.stderr  # the flag, once the CLI renders it


@pytest.mark.parametrize("source_fps", [0.0, -30.0, float("nan"), float("inf"), 1e308, 1e-320, 0.05, 20_000.0, "30"])
def test_source_fps_is_bounded(source_fps):
    clip = read_bvh(DEMO_CLIP)
    with pytest.raises(OptionError) as info:
        build_codec(clip, source_fps=source_fps)
    assert info.value.option == "source_fps"
    codec = build_codec(clip)
    with pytest.raises(OptionError):
        codec.encode(clip, source_fps=source_fps)


@pytest.mark.parametrize("value", ["1e39", "-3.5e38", "1e308"])
def test_values_beyond_float32_name_their_line(tmp_path, value):
    path = write_clip(tmp_path, clip_text(3, value=value))
    with pytest.raises(BVHError) as info:
        read_bvh(path)
    assert info.value.line == FRAME_TIME_LINE + 1 and "beyond the float32 range" in info.value.message


def test_offsets_beyond_float32_name_their_line(tmp_path):
    path = write_clip(tmp_path, clip_text(3).replace("OFFSET 0 10 0", "OFFSET 0 -1e39 0"))
    with pytest.raises(BVHError) as info:
        read_bvh(path)
    assert info.value.line == 8 and "float32" in info.value.message


def test_positions_absurd_after_units_are_refused_naming_the_file(tmp_path):
    path = write_clip(tmp_path, clip_text(3, value="1e30"))
    with pytest.raises(SinMDMError, match=f"^{path} has positions beyond"):
        build_codec(read_bvh(path), units="m")
    codec = build_codec(read_bvh(DEMO_CLIP))
    huge = read_bvh(write_clip(tmp_path, _scaled_root(DEMO_CLIP, 1e30), "far.bvh"))
    with pytest.raises(SinMDMError, match="has positions beyond"):
        codec.encode(huge)


def _scaled_root(path: Path, value: float) -> str:
    """The demo clip with its first channel (a root position) set to `value` on every frame."""
    text = path.read_text()
    head, data = text.split("Frame Time:", 1)
    time_line, *rows = data.split("\n")
    rows = [" ".join([repr(value)] + row.split()[1:]) if row.strip() else row for row in rows]
    return head + "Frame Time:" + time_line + "\n" + "\n".join(rows)


@pytest.mark.parametrize("units", [0, -1.0, float("nan"), float("inf"), 1e-9, "1e9", "nan"])
def test_units_are_bounded(units):
    skeleton = read_bvh(DEMO_CLIP).skeleton
    with pytest.raises(OptionError) as info:
        unit_scale(skeleton, units)
    assert info.value.option == "units"


def test_a_channel_less_skeleton_with_an_absurd_frame_count_names_its_line(tmp_path):
    text = "HIERARCHY\nROOT a\n{\n\tOFFSET 0 0 0\n\tCHANNELS 0\n}\nMOTION\nFrames: 99999999999999999999\nFrame Time: 0.1\n"
    path = write_clip(tmp_path, text)
    with pytest.raises(BVHError) as info:
        read_bvh(path)
    assert info.value.line == 8 and "joint-frames" in info.value.message
    # Under the memory bound, a channel-less file must still have one (empty) line per frame.
    with pytest.raises(BVHError, match="declared 50000 frames but the file has 1 lines"):
        read_bvh(write_clip(tmp_path, text.replace("99999999999999999999", "50000"), "short.bvh"))
    assert_one_line_exit_2(run_cli("sinmdm-run", "inspect", str(path)), path)


def test_a_fifo_is_refused_at_once(tmp_path):
    fifo = tmp_path / "clip.bvh"
    os.mkfifo(fifo)
    started = time.perf_counter()
    with pytest.raises(SinMDMError, match=f"^cannot read {fifo}: not a regular file"):
        read_bvh(fifo)
    assert time.perf_counter() - started < 1.0


def test_a_device_is_refused_unread():
    with pytest.raises(SinMDMError, match="^cannot read /dev/zero: not a regular file"):
        read_bvh("/dev/zero")


def test_a_file_over_the_size_cap_is_refused_unread(tmp_path):
    path = tmp_path / "huge.bvh"
    with open(path, "wb") as fh:
        fh.truncate((1 << 30) + 1)  # sparse: no disk used
    started = time.perf_counter()
    with pytest.raises(SinMDMError, match=f"^cannot read {path}: larger than the 1 GiB"):
        read_bvh(path)
    assert time.perf_counter() - started < 1.0

