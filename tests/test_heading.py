"""The heading frame (`--root-frame heading`): the trajectory joint seen from the
character's heading, plus its rate of turn. Going there and back is exact on every
layout; a model trained in it samples motion, and what it cannot do yet is refused
before any work with one line; the applications keep what they keep."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sinmdm.runtime import load_model
from sinmdm.runtime.animation import animation_from_bvh, global_positions
from sinmdm.runtime.applications import INBETWEEN_RAMP
from sinmdm.runtime.bvh import read_bvh
from sinmdm.runtime.features import build_codec, resample_animation
from sinmdm.runtime.generate import generate
from sinmdm.runtime.graph_space import graph_space
from sinmdm.runtime.heading import clip_heading_frame, close_the_turn
from sinmdm.runtime.options import SamplingOptions

from .conftest import TINY_TRAIN_ARGS, call_cli, real_clip
from .layouts import with_static_root, z_up

LAYOUTS = {"as shared": lambda b: b, "z-up": z_up, "static root": with_static_root}


@pytest.mark.parametrize("layout", LAYOUTS)
@pytest.mark.parametrize("name", ["Joe_Walk-In-Circle.bvh", "Crabnew_Crab-dance-long.bvh", "Elephant_idle1.bvh"])
def test_there_and_back_is_exact(name, layout):
    clip = LAYOUTS[layout](read_bvh(real_clip(name)))
    codec = build_codec(clip, fps=30)
    features = codec.encode(clip).astype(np.float64)
    frame = clip_heading_frame(codec, features)
    graph = frame.to_graph(features)
    assert graph.shape == (len(features), codec.width + 1)
    np.testing.assert_allclose(frame.to_features(graph), features, atol=1e-6)


@pytest.mark.parametrize("layout", LAYOUTS)
def test_the_walk_in_a_circle_is_one_turn_rate_and_one_forward_speed(layout):
    """What varies with the heading in the world (rotation, velocity direction) is constant in
    the heading frame: the same pattern in every window, which a narrow model can learn."""
    clip = LAYOUTS[layout](read_bvh(real_clip("Joe_Walk-In-Circle.bvh")))
    codec = build_codec(clip, fps=30)
    features = codec.encode(clip).astype(np.float64)
    frame = clip_heading_frame(codec, features)
    graph = frame.to_graph(features)
    turn = np.degrees(graph[:, -1])
    assert np.mean(turn) == pytest.approx(29, abs=2)  # deg/s, to the left (counter-clockwise from above)
    velocity = graph[:, list(frame.velocity)] * codec.fps
    world = features[:, list(frame.velocity)] * codec.fps
    assert velocity.std(axis=0).max() < 0.5 * world.std(axis=0).max()  # the world velocity goes round, this does not


def test_graph_space_scales_after_turning():
    clip = read_bvh(real_clip("Joe_Walk-In-Circle.bvh"))
    codec = build_codec(clip, fps=30)
    features = codec.encode(clip).astype(np.float64)
    frame = clip_heading_frame(codec, features).to_dict()
    space = graph_space(codec, {"velocity_unit": "second", "heading_frame": frame})
    graph = space.to_graph(features)
    assert graph.shape[-1] == space.width == codec.width + 1
    np.testing.assert_allclose(space.to_features(graph), features, atol=1e-6)


@pytest.fixture(scope="module")
def heading_model(tmp_path_factory):
    """A tiny model of the walk trained in the heading frame, exported."""
    work = tmp_path_factory.mktemp("heading")
    clip = real_clip("Joe_Walk-In-Circle.bvh")
    call_cli("sinmdm", "train", str(clip), "--out", str(work / "run"), "--steps", "6", *TINY_TRAIN_ARGS,
             "--root-frame", "heading", check=True)
    call_cli("sinmdm", "export", str(work / "run"), "--out", str(work / "walk.onnx"), check=True)
    return work / "walk_w48.onnx", clip, work


def test_a_heading_model_says_so_and_samples_the_same_bytes_twice(heading_model):
    path, clip, work = heading_model
    model = load_model(path)
    assert model.graph_width == model.features + 1 and model.graph_space.heading is not None
    config = json.loads((work / "run" / "config.json").read_text())
    assert config["train"]["root_frame"] == "heading" and len(config["heading_frame"]["forward"]) == 3
    info = call_cli("sinmdm", "info", str(work / "run"), check=True)
    assert "root frame" in info.stdout + info.stderr
    a = generate(model, 120, SamplingOptions(count=2, seed=3, steps=5))
    b = generate(model, 120, SamplingOptions(count=2, seed=3, steps=5))
    assert np.array_equal(a.features, b.features) and np.isfinite(a.features).all()
    one = generate(model, 120, SamplingOptions(count=1, seed=4, steps=5))  # the second sample of the crowd, alone
    assert np.array_equal(one.features[0], a.features[1])


@pytest.mark.parametrize("args", [
    ["control", "--ref", "TRAJECTORY", "--trajectory", "--source-fps", "30"],  # a path of another skeleton: no heading
])
def test_what_a_heading_model_cannot_do_is_refused_in_one_line(heading_model, args, tmp_path):
    path, clip, _ = heading_model
    args = [str(real_clip("Joe_traj-example.bvh")) if a == "TRAJECTORY" else a for a in args]
    result = call_cli("sinmdm-run", args[0], str(path), *args[1:], "--out", str(tmp_path / "out"))
    assert result.returncode == 2, result.stdout + result.stderr
    message = (result.stdout + result.stderr).strip()
    assert "--root-frame" in message and len(message.splitlines()) == 1 and "Traceback" not in message
    assert not (tmp_path / "out").exists()  # refused before the output folder is made


def _hips(path) -> tuple[np.ndarray, np.ndarray]:
    animation = resample_animation(animation_from_bvh(read_bvh(path)), 30)
    return animation.rotations[:, 0], global_positions(animation)[:, 0]


def test_in_betweening_keeps_the_reference_s_start_and_end_exactly(heading_model, tmp_path):
    """The heading is integrated from the reference's on the first kept frame and what the
    generated gap misses is spread over it, so the kept end faces and stands where the clip's does."""
    path, clip, _ = heading_model
    call_cli("sinmdm-run", "inbetween", str(path), "--ref", str(clip), "--out", str(tmp_path), "--steps", "5", check=True)
    rotations, positions = _hips(next(tmp_path.glob("*.bvh")))
    want_rotations, want_positions = _hips(clip)
    quarter = len(rotations) // 4 - INBETWEEN_RAMP
    for kept in (slice(0, quarter), slice(len(rotations) - quarter, None)):
        np.testing.assert_allclose(rotations[kept], want_rotations[kept], atol=1e-3)
        np.testing.assert_allclose(positions[kept], want_positions[kept], atol=0.05)  # file units (cm)


def test_trajectory_control_walks_the_reference_s_path(heading_model, tmp_path):
    path, clip, _ = heading_model
    call_cli("sinmdm-run", "control", str(path), "--ref", str(clip), "--trajectory", "--out", str(tmp_path), "--steps", "5",
             check=True)
    rotations, positions = _hips(next(tmp_path.glob("*.bvh")))
    want_rotations, want_positions = _hips(clip)
    np.testing.assert_allclose(positions[:, [0, 2]], want_positions[:, [0, 2]], atol=0.05)
    np.testing.assert_allclose(rotations, want_rotations, atol=1e-3)


@pytest.mark.parametrize("app", ["expand", "keyframes", "harmonize"])
def test_the_other_applications_run_on_a_heading_model(heading_model, app, tmp_path):
    path, clip, _ = heading_model
    call_cli("sinmdm-run", app, str(path), "--ref", str(clip), "--out", str(tmp_path), "--steps", "5", check=True)
    rotations, positions = _hips(next(tmp_path.glob("*.bvh")))
    assert np.isfinite(positions).all() and len(rotations) > 300


def test_bad_root_frame_options_are_refused_before_training(tmp_path):
    clip = str(real_clip("Joe_Walk-In-Circle.bvh"))
    bad = call_cli("sinmdm", "train", clip, "--out", str(tmp_path / "a"), "--root-frame", "body", "--steps", "2")
    assert bad.returncode == 2 and "--root-frame" in bad.stdout + bad.stderr


def test_the_foot_loss_trains_in_the_heading_frame(tmp_path):
    clip = str(real_clip("Joe_Walk-In-Circle.bvh"))
    call_cli("sinmdm", "train", clip, "--out", str(tmp_path / "b"), "--root-frame", "heading", "--foot-loss", "0.001",
             "--foot-loss-target", "clip", "--steps", "2", *TINY_TRAIN_ARGS, check=True)
    shown = call_cli("sinmdm", "info", str(tmp_path / "b"), "--json", check=True)
    summary = json.loads(shown.stdout)
    assert summary["root_frame"]["frame"] == "heading" and summary["foot_loss"]["on"]
    assert "matched to the clip's" in summary["foot_loss"]["why"]


@pytest.mark.parametrize("frames, turns", [(100, 0), (400, 1), (1300, 4)])
def test_a_loop_turns_whole_turns(frames, turns):
    """30 deg/s for 100 frames (100 deg) loops facing one way; for 400 frames (400 deg), one circle;
    the difference is spread evenly, so the wrap turns like every other frame."""
    x = np.zeros((1, 5, frames), dtype=np.float32)
    x[:, -1] = np.radians(30.0)  # rad/s at 30 fps
    x = close_the_turn(x, 30.0)
    assert x[0, -1].sum() / 30.0 == pytest.approx(2 * np.pi * turns, abs=1e-4)
    assert np.ptp(x[0, -1]) < 1e-6


def test_a_heading_model_samples_loops(heading_model):
    path, _, _ = heading_model
    result = generate(load_model(path), 120, SamplingOptions(count=2, seed=0, steps=5), loop=True)
    assert result.loop_displacement.shape == (2, 2) and np.isfinite(result.features).all()


@pytest.mark.parametrize("args", [["--frames", "120", "--steps", "4"], ["--frames", "100", "--loop", "--steps", "4"]])
def test_the_node_port_reproduces_a_heading_model_s_vectors(heading_model, args, tmp_path):
    """The golden vectors hold the chain in the graph's space (F + 1 channels); the Node port turns
    the heading back as the runtime does (ports/node/lib/sampler.js)."""
    from .test_node_port import TOLERANCE, run_check

    path, _, _ = heading_model
    call_cli("sinmdm-run", "vectors", str(path), "--out", str(tmp_path / "v"), "--threads", "1", *args, check=True)
    manifest = json.loads((tmp_path / "v" / "manifest.json").read_text())
    assert manifest["graph_width"] == manifest["features"] + 1
    result = run_check(path, tmp_path / "v", "--json")
    assert result.returncode == 0, result.stdout + result.stderr
    report = json.loads(result.stdout)
    assert report["ok"] and report["features"] <= TOLERANCE and report["positions_of_size"] <= TOLERANCE


@pytest.mark.parametrize("name, frame", [("Joe_Walk-In-Circle.bvh", "heading"), ("Crabnew_Crab-dance-long.bvh", "world"),
                                         ("Joe_Baseball-Milling-Idle.bvh", "world"), ("Xia_proud.bvh", "world")])
def test_the_cpu_preset_chooses_the_heading_frame_for_a_clip_that_turns_steadily(name, frame):
    from sinmdm.train.presets import preset
    from sinmdm.train.trainer import choose_root_frame, load_clip

    options = {"units": "auto", "source_fps": None, "root": None, "up": "auto", "contacts": "auto"}
    clip = load_clip(real_clip(name), 30.0, options)
    heading = clip_heading_frame(clip.codec, clip.features)
    chosen, why = choose_root_frame(clip, preset("cpu"), heading)
    assert chosen == frame and why.startswith("auto: the clip turns")
    assert choose_root_frame(clip, preset("paper"), heading) == ("world", "asked for")  # the paper's features, always


def test_a_walk_in_a_circle_on_a_production_layout_is_trained_in_the_heading_frame(tmp_path):
    from sinmdm.runtime.bvh import write_bvh

    clip = tmp_path / "walk_static_root_z_up.bvh"
    write_bvh(clip, z_up(with_static_root(read_bvh(real_clip("Joe_Walk-In-Circle.bvh")))))
    call_cli("sinmdm", "train", str(clip), "--out", str(tmp_path / "run"), "--steps", "2", *TINY_TRAIN_ARGS, check=True)
    config = json.loads((tmp_path / "run" / "config.json").read_text())
    assert config["root_frame"]["frame"] == "heading" and config["train"]["root_frame"] == "auto"
    info = call_cli("sinmdm", "info", str(tmp_path / "run"), check=True)
    assert "heading (auto: the clip turns +28.7 deg/s" in " ".join((info.stdout + info.stderr).split())
