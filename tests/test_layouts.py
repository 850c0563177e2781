"""Production skeleton layouts, derived in code from the shared clips: the runtime
finds the joint that carries the character, the up axis and the feet on every
layout, writes static joints back exactly, and every command runs on them."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sinmdm.runtime.animation import animation_from_bvh, global_positions
from sinmdm.runtime.bvh import read_bvh, write_bvh
from sinmdm.runtime.features import build_codec, skeleton_size
from sinmdm.runtime.masks import body_halves

from .conftest import REAL_CLIPS, TINY_TRAIN_ARGS, real_clip, run_cli
from .layouts import LAYOUTS, scaled, with_static_root, z_up

TRAINABLE = [p.name for p in REAL_CLIPS if "traj-example" not in p.name and "keyframes" not in p.name]
ADDED_ROOT = {"static-root": "joint_Root", "static-root-z-up": "joint_Root", "armature": "Armature"}


@pytest.fixture(scope="module", params=TRAINABLE)
def original(request):
    clip = read_bvh(real_clip(request.param))
    return clip, build_codec(clip)


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_every_layout_finds_the_same_root_up_axis_and_feet(original, layout):
    clip, codec = original
    derived = LAYOUTS[layout](clip)
    got = build_codec(derived)
    names, own = derived.skeleton.names, clip.skeleton.names
    assert names[got.trajectory_joint] == own[codec.trajectory_joint]
    assert [names[j] for j in got.fixed_joints] == ([ADDED_ROOT[layout]] if layout in ADDED_ROOT else [])
    assert got.up_axis == (2 if "z-up" in layout else 1) and codec.up_axis == 1
    assert [names[j] for j in got.contact_joints] == [own[j] for j in codec.contact_joints]
    assert got.width == codec.width  # a static root adds no features


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_round_trip_keeps_the_motion_and_the_static_root_exactly(layout):
    clip = LAYOUTS[layout](read_bvh(real_clip("Xia_normal.bvh")))
    codec = build_codec(clip, fps=clip.fps)
    out = codec.decode_bvh(codec.encode(clip), codec.start_position(clip))
    error = np.abs(global_positions(animation_from_bvh(clip)) - global_positions(animation_from_bvh(out))).max()
    assert error < 1e-5 * skeleton_size(clip.skeleton)
    if layout in ADDED_ROOT:
        columns = len(clip.skeleton.channels[0])
        assert np.array_equal(out.values[:, :columns], clip.values[:, :columns])


def test_units_do_not_change_the_features():
    clip = read_bvh(real_clip("Xia_normal.bvh"))  # cm
    metres = scaled(clip, 0.01)
    cm_codec, m_codec = build_codec(clip), build_codec(metres)
    assert (cm_codec.scale, m_codec.scale) == (0.01, 1.0)
    assert np.allclose(cm_codec.encode(clip), m_codec.encode(metres), atol=1e-5)


@pytest.mark.parametrize("layout", ["static-root", "static-root-z-up", "armature"])
def test_body_halves_come_from_the_real_pelvis(layout):
    clip = read_bvh(real_clip("Joe_Walk-In-Circle.bvh"))
    upper, lower = body_halves(build_codec(clip))
    got_upper, got_lower = body_halves(build_codec(LAYOUTS[layout](clip)))
    assert got_lower == lower and got_upper == upper | {ADDED_ROOT[layout]}


def test_inspect_names_the_choice_and_takes_overrides(tmp_path):
    path = tmp_path / "bandai_like.bvh"
    write_bvh(path, z_up(with_static_root(read_bvh(real_clip("Joe_Walk-In-Circle.bvh")))))
    info = json.loads(run_cli("sinmdm-run", "inspect", str(path), "--json", check=True).stdout)
    hips = "mixamorig7:Hips"
    assert (info["trajectory_joint"], info["fixed_joints"], info["up_axis"]) == (hips, ["joint_Root"], "z")
    assert "joint_Root" not in info["contact_joints"] and len(info["contact_joints"]) == 6
    assert any(hips in why for why in info["why"]) and not info["warnings"]
    forced = json.loads(run_cli("sinmdm-run", "inspect", str(path), "--json", "--up", "y", "--root", "joint_Root",
                                check=True).stdout)
    assert (forced["trajectory_joint"], forced["up_axis"]) == ("joint_Root", "y")
    bad = run_cli("sinmdm-run", "inspect", str(path), "--up", "x")
    assert bad.returncode == 2 and "up axis" in bad.stderr and "Traceback" not in bad.stderr


def test_implausible_size_warns_about_units(tmp_path):
    path = tmp_path / "tiny_units.bvh"
    write_bvh(path, scaled(read_bvh(real_clip("Joe_Walk-In-Circle.bvh")), 0.001))  # a 2 mm figure read as metres
    info = json.loads(run_cli("sinmdm-run", "inspect", str(path), "--json", check=True).stdout)
    assert any("--units" in w for w in info["warnings"])


def test_every_command_runs_on_a_static_root_z_up_clip(tmp_path):
    """train (a tiny run), export, sample, every application, eval and preview."""
    clip = tmp_path / "bandai_like.bvh"
    write_bvh(clip, z_up(with_static_root(read_bvh(real_clip("Xia_normal.bvh")))))
    run = tmp_path / "run"
    run_cli("sinmdm", "train", str(clip), "--out", str(run), "--steps", "6", *TINY_TRAIN_ARGS, check=True)
    run_cli("sinmdm", "export", str(run), "--out", str(tmp_path / "m.onnx"), check=True)
    model = str(tmp_path / "m_w48.onnx")
    out = tmp_path / "out"
    files = json.loads(run_cli("sinmdm-run", "sample", model, "--frames", "100", "--steps", "3", "--out", str(out),
                               "--json", check=True).stdout)["files"]
    sample = read_bvh(files[0])
    assert sample.skeleton.names == read_bvh(clip).skeleton.names
    source = read_bvh(clip)
    assert np.array_equal(sample.values[:, :6], np.broadcast_to(source.values[0, :6], (sample.frames, 6)))
    for command, extra in [("inbetween", []), ("expand", []), ("keyframes", ["--every", "45"]),
                           ("control", ["--joints", "upper-body"]), ("control", ["--trajectory"]),
                           ("harmonize", [])]:
        run_cli("sinmdm-run", command, model, "--ref", str(clip), "--steps", "3", "--out", str(out / command),
                "--force", *extra, check=True)
    scores = json.loads(run_cli("sinmdm", "eval", str(clip), *files, "--json", check=True).stdout)
    assert 0 <= scores["coverage"] <= 100
    pytest.importorskip("matplotlib")
    run_cli("sinmdm-run", "preview", files[0], "--out", str(tmp_path / "p.gif"), check=True)


def test_a_z_up_path_drives_a_y_up_model_along_the_same_floor_plan(tmp_path):
    from sinmdm.runtime.applications import load_trajectory
    from sinmdm.runtime.model import load_model

    model = load_model()  # the bundled demo model is Y-up
    source = real_clip("Joe_traj-example.bvh")
    rotated = tmp_path / "path_z_up.bvh"
    write_bvh(rotated, z_up(read_bvh(source)))
    y_path, z_path = load_trajectory(model, source, 30.0), load_trajectory(model, rotated, 30.0)
    assert np.allclose(y_path.features, z_path.features, atol=1e-9) and np.allclose(y_path.start, z_path.start)


@pytest.mark.parametrize("frames", [1, 2, 3])
def test_a_clip_too_short_to_judge_by_the_feet_stands_on_its_taller_axis(frames):
    from sinmdm.runtime.bvh import BVH

    bvh = read_bvh(real_clip("Xia_normal.bvh"))
    short = BVH(bvh.skeleton, bvh.frame_time, bvh.values[:frames])
    assert build_codec(short).up_axis == 1
    assert build_codec(z_up(short)).up_axis == 2


def test_convert_to_glb_takes_root_and_up(tmp_path):
    source = tmp_path / "clip.bvh"
    write_bvh(source, z_up(with_static_root(read_bvh(real_clip("Xia_normal.bvh")))))
    for up in ("auto", "z"):
        target = tmp_path / f"clip-{up}.glb"
        result = run_cli("sinmdm-run", "convert", str(source), str(target), "--up", up, "--root", "Hips")
        assert result.returncode == 0, result.stderr
        assert target.stat().st_size > 0
    result = run_cli("sinmdm-run", "convert", str(source), str(tmp_path / "bad.glb"), "--up", "x")
    assert result.returncode == 2 and "Traceback" not in result.stderr and not (tmp_path / "bad.glb").exists()
