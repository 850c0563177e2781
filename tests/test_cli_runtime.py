"""`sinmdm-run inspect|convert` as real processes: output, JSON, errors, no torch."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sinmdm.runtime.animation import animation_from_bvh, global_positions
from sinmdm.runtime.bvh import read_bvh
from sinmdm.runtime.features import skeleton_size

from .conftest import DEMO_CLIP, REAL_CLIPS, ROOT, WRONG_FRAME_TIME, run_cli

BAD_CORPUS = sorted((ROOT / "tests" / "data" / "bvh_bad").glob("*.bvh"))


def test_inspect_json(no_torch_env):
    result = run_cli("sinmdm-run", "inspect", str(DEMO_CLIP), "--json", env=no_torch_env, check=True)
    info = json.loads(result.stdout)
    assert info["joints"] == 19 and info["frames"] == 360 and info["fps"] == pytest.approx(30)
    assert info["contact_joints"] == ["LeftToe", "RightToe"]
    assert info["metres_per_unit"] == 0.01
    assert info["feature_width"] == 19 * 6 + 2 + 3


def test_inspect_rich_output():
    result = run_cli("sinmdm-run", "inspect", str(DEMO_CLIP), check=True)
    text = result.stdout + result.stderr
    assert "LeftForeArm" in text and "feature width" in text


def test_convert_round_trip_without_torch(tmp_path, no_torch_env):
    out = tmp_path / "out.bvh"
    result = run_cli("sinmdm-run", "convert", str(DEMO_CLIP), str(out), "--json", env=no_torch_env, check=True)
    summary = json.loads(result.stdout)
    assert summary["max_position_error_of_size"] < 1e-3
    original, converted = read_bvh(DEMO_CLIP), read_bvh(out)
    assert converted.skeleton.names == original.skeleton.names
    assert converted.skeleton.channels == original.skeleton.channels
    assert converted.frame_time == pytest.approx(original.frame_time)


@pytest.mark.realdata
@pytest.mark.parametrize("path", REAL_CLIPS, ids=lambda p: p.name)
def test_convert_round_trips_every_real_clip(tmp_path, path):
    out = tmp_path / path.name
    args = ["sinmdm-run", "convert", str(path), str(out), "--json"]
    if path.name in WRONG_FRAME_TIME:
        args += ["--source-fps", str(WRONG_FRAME_TIME[path.name])]
    run_cli(*args, check=True)
    original, converted = read_bvh(path), read_bvh(out)
    assert converted.skeleton.names == original.skeleton.names
    assert converted.skeleton.channels == original.skeleton.channels
    assert converted.frames == original.frames
    if path.name not in WRONG_FRAME_TIME:
        assert converted.frame_time == pytest.approx(original.frame_time, rel=1e-3)
    p0 = global_positions(animation_from_bvh(original))
    p1 = global_positions(animation_from_bvh(converted))
    assert np.abs(p0 - p1).max() / skeleton_size(original.skeleton) < 1e-3


def test_convert_to_30_fps(tmp_path):
    out = tmp_path / "half.bvh"
    run_cli("sinmdm-run", "convert", str(DEMO_CLIP), str(out), "--fps", "15", check=True)
    assert read_bvh(out).frames == 180
    assert read_bvh(out).frame_time == pytest.approx(1 / 15)


def test_convert_refuses_to_overwrite(tmp_path):
    out = tmp_path / "x.bvh"
    out.write_text("keep me")
    result = run_cli("sinmdm-run", "convert", str(DEMO_CLIP), str(out))
    assert result.returncode == 2 and "--force" in result.stderr
    assert out.read_text() == "keep me"


@pytest.mark.parametrize("path", BAD_CORPUS, ids=lambda p: p.name)
@pytest.mark.parametrize("command", ["inspect", "convert"])
def test_malformed_files_exit_2_with_one_line(tmp_path, path, command):
    out = tmp_path / "out.bvh"
    args = ["sinmdm-run", command, str(path)] + ([str(out)] if command == "convert" else [])
    result = run_cli(*args)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert str(path) in lines[0] and "Traceback" not in result.stderr
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []  # no partial file either


def test_missing_file_is_a_clean_error(tmp_path):
    result = run_cli("sinmdm-run", "inspect", str(tmp_path / "nope.bvh"))
    assert result.returncode == 2 and "nope.bvh" in result.stderr and "Traceback" not in result.stderr


def test_import_runtime_loads_no_torch():
    import subprocess
    import sys

    code = "import sys, sinmdm.runtime, sinmdm.runtime.features, sinmdm.runtime.bvh, sinmdm.cli.run; assert 'torch' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True)


def test_version():
    from sinmdm import __version__

    for command in ("sinmdm-run", "sinmdm"):
        result = run_cli(command, "--version", check=True)
        assert result.stdout.strip() == f"{command} {__version__}"
