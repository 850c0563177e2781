"""The root velocity in metres per second (`--velocity-unit second`): the model trains and
samples with the root's horizontal velocity channels multiplied by the frame rate, and
everything outside the sampler (features, guides, BVH, vectors) stays in metres per frame."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from sinmdm.runtime.errors import SinMDMError
from sinmdm.runtime.features import model_scale
from sinmdm.runtime.model import load_model
from sinmdm.runtime.options import SamplingOptions
from sinmdm.runtime.sampler import Guide, sample_features
from sinmdm.runtime.vectors import read_array

from .conftest import DEMO_CLIP, TINY_TRAIN_ARGS, call_cli, run_cli
from .test_node_port import run_check


@pytest.fixture(scope="module")
def per_second(tmp_path_factory):
    """A tiny real run on the demo clip trained with --velocity-unit second, exported."""
    root = tmp_path_factory.mktemp("per_second")
    run_cli("sinmdm", "train", str(DEMO_CLIP), "--out", str(root / "run"), "--steps", "10", *TINY_TRAIN_ARGS,
            "--velocity-unit", "second", check=True)
    run_cli("sinmdm", "export", str(root / "run"), "--out", str(root / "m.onnx"), check=True)
    return root


def root_velocity(codec) -> list[int]:
    dx, _, dz = codec.layout.indices(("root",))
    return [int(dx), int(dz)]


def test_model_scale_multiplies_only_the_horizontal_root_velocity(tiny_model):
    codec = load_model(tiny_model).codec
    assert model_scale(codec, "frame") is None
    scale = model_scale(codec, "second")
    velocity = root_velocity(codec)
    assert scale.shape == (codec.width,) and (scale[velocity] == codec.fps).all()
    assert (np.delete(scale, velocity) == 1).all()
    with pytest.raises(SinMDMError, match="velocity unit"):
        model_scale(codec, "minute")


def test_the_run_and_the_exported_model_say_their_unit(per_second):
    config = json.loads((per_second / "run" / "config.json").read_text())
    assert config["train"]["velocity_unit"] == "second"
    model = load_model(per_second / "m_w48.onnx")
    assert model.metadata["velocity_unit"] == "second" and model.velocity_unit == "second"
    assert json.loads((per_second / "m_w48.json").read_text())["velocity_unit"] == "second"


def test_sampled_features_come_back_in_metres_per_frame(per_second):
    model = load_model(per_second / "m_w48.onnx", threads=1)
    as_frame = dataclasses.replace(model, metadata={**model.metadata, "velocity_unit": "frame"})
    options = SamplingOptions(count=2, seed=5, steps=4)
    graph_space = sample_features(as_frame, 120, options)  # the same chain, read without the scale
    features = sample_features(model, 120, options)
    velocity = root_velocity(model.codec)
    fps = np.float32(model.codec.fps)
    np.testing.assert_array_equal(features[..., velocity], graph_space[..., velocity] / fps)
    np.testing.assert_array_equal(np.delete(features, velocity, -1), np.delete(graph_space, velocity, -1))


def test_a_guide_is_given_in_metres_per_frame(per_second):
    """What an application keeps comes back as it gave it, though the graph saw it x fps."""
    model = load_model(per_second / "m_w48.onnx", threads=1)
    frames = 96
    reference = np.zeros((model.features, frames))
    velocity = root_velocity(model.codec)
    reference[velocity[0]], reference[velocity[1]] = 0.02, -0.01  # 0.6 and 0.3 m/s at 30 fps
    keep = np.zeros_like(reference)
    keep[velocity] = 1.0
    features = sample_features(model, frames, SamplingOptions(seed=1, steps=6), Guide(reference, keep))[0]
    np.testing.assert_allclose(features[:, velocity[0]], 0.02, atol=1e-6)
    np.testing.assert_allclose(features[:, velocity[1]], -0.01, atol=1e-6)


def test_the_vectors_hold_the_graphs_chain_and_the_scaled_back_features(per_second, tmp_path):
    model_path = per_second / "m_w48.onnx"
    model = load_model(model_path, threads=1)
    out = tmp_path / "vectors"
    call_cli("sinmdm-run", "vectors", str(model_path), "--out", str(out), "--frames", "100", "--steps", "3",
             "--threads", "1", check=True)
    document = json.loads((out / "manifest.json").read_text())
    arrays = {key: read_array(out, document, key) for key in ("x_0", "features")}
    features = sample_features(model, 100, SamplingOptions(steps=3, seed=document["options"]["seed"]))[0]
    np.testing.assert_array_equal(arrays["features"], features)
    margin = document["options"]["margin"]
    np.testing.assert_array_equal(arrays["features"],
                                  (arrays["x_0"][:, margin : margin + 100] / model.graph_space.scale[:, None].astype(np.float32)).T)
    result = run_check(model_path, out, "--json")  # skips without node and onnxruntime-node
    assert result.returncode == 0, result.stdout + result.stderr
    report = json.loads(result.stdout)
    assert report["ok"] and report["features"] == 0.0


def test_an_unknown_unit_is_refused_in_one_line(tmp_path):
    result = call_cli("sinmdm", "train", str(DEMO_CLIP), "--out", str(tmp_path / "r"), "--steps", "2",
                      "--velocity-unit", "minute")
    assert result.returncode == 2 and "--velocity-unit" in result.stderr and result.stderr.count("\n") == 1
    assert not (tmp_path / "r").exists()
