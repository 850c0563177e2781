"""The torch-free runtime: loading, sampling, determinism, any length, crowds, errors."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import onnx
import pytest

from sinmdm.runtime import SamplingOptions, generate, load_model, read_bvh, write_outputs
from sinmdm.runtime.model import DEMO_MODEL
from sinmdm.runtime.sampler import blend_weights, low_pass, window_starts

from .conftest import DEMO_CLIP, run_cli


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def sample(model: Path, out: Path, *args: str, env: dict | None = None, check: bool = True):
    return run_cli("sinmdm-run", "sample", str(model), "--out", str(out), "--steps", "8", *args, env=env, check=check)


def test_same_seed_same_bytes_and_seeds_differ(tiny_model, tmp_path, no_torch_env):
    sample(tiny_model, tmp_path / "a", "--frames", "90", "--count", "2", "--seed", "5", env=no_torch_env)
    sample(tiny_model, tmp_path / "b", "--frames", "90", "--count", "2", "--seed", "5", env=no_torch_env)
    sample(tiny_model, tmp_path / "c", "--frames", "90", "--count", "1", "--seed", "6", env=no_torch_env)
    a = sorted((tmp_path / "a").glob("*.bvh"))
    assert [p.name for p in a] == ["sample_0005.bvh", "sample_0006.bvh"]
    assert digest(a[0]) == digest(tmp_path / "b" / "sample_0005.bvh")
    assert digest(a[0]) != digest(a[1])
    # sample i of a crowd is reproducible alone with seed + i
    assert digest(a[1]) == digest(tmp_path / "c" / "sample_0006.bvh")


def test_long_motion_from_a_short_window(tiny_model, tmp_path, no_torch_env):
    result = sample(tiny_model, tmp_path, "--frames", "1000", "--json", env=no_torch_env)
    summary = json.loads(result.stdout)
    clip = read_bvh(summary["files"][0])
    assert clip.frames == 1000 and clip.frame_time == pytest.approx(1 / 30)
    assert clip.skeleton.names == read_bvh(DEMO_CLIP).skeleton.names
    assert clip.skeleton.channels == read_bvh(DEMO_CLIP).skeleton.channels


def test_shorter_than_window_and_seconds(tiny_model, tmp_path):
    sample(tiny_model, tmp_path / "short", "--frames", "20")
    assert read_bvh(tmp_path / "short" / "sample_0000.bvh").frames == 20
    sample(tiny_model, tmp_path / "secs", "--seconds", "2.5")
    assert read_bvh(tmp_path / "secs" / "sample_0000.bvh").frames == 75


def test_crowd_of_16(tiny_model, tmp_path):
    sample(tiny_model, tmp_path, "--frames", "60", "--count", "16", "--npz")
    clips = sorted(tmp_path.glob("*.bvh"))
    assert len(clips) == 16 and len(set(map(digest, clips))) == 16
    data = np.load(tmp_path / "sample_0000.npz")
    assert data["features"].shape == (60, 119) and data["positions_m"].shape == (60, 19, 3)


def test_ddim_is_deterministic_and_full_ddpm_runs(tiny_model, tmp_path):
    model = load_model(tiny_model)
    a = generate(model, 50, SamplingOptions(seed=1, sampler="ddim", steps=5))
    b = generate(model, 50, SamplingOptions(seed=2, sampler="ddim", steps=5))
    assert a.features.shape == (1, 50, model.features)
    assert not np.array_equal(a.features, b.features)  # different initial noise
    full = generate(model, 48, SamplingOptions(seed=0, steps=1000))
    assert np.isfinite(full.features).all()


def test_python_api_writes_atomically(tiny_model, tmp_path):
    model = load_model([tiny_model])
    result = generate(model, 64, SamplingOptions(count=2, seed=3, steps=4))
    paths = write_outputs(model, result, tmp_path / "api")
    assert [p.name for p in paths] == ["sample_0003.bvh", "sample_0004.bvh"]
    assert not list((tmp_path / "api").glob(".*"))  # no temporary files left


def test_windows_cover_and_cross_fade():
    starts = window_starts(1000, 64, 32)
    assert starts[0] == 0 and starts[-1] == 1000 - 64 and np.all(np.diff(starts) <= 32)
    weights = blend_weights(64)
    assert weights.min() > 0 and weights[0] == weights[-1]
    x = np.random.default_rng(0).standard_normal((2, 3, 40))
    assert low_pass(x, 1) is x
    smooth = low_pass(x, 2)
    assert smooth.shape == x.shape and np.abs(np.diff(smooth, axis=-1)).mean() < np.abs(np.diff(x, axis=-1)).mean()


def test_bundled_demo_model_loads_with_current_format():
    assert DEMO_MODEL.exists()
    model = load_model()
    assert model.codec.skeleton.names == read_bvh(DEMO_CLIP).skeleton.names
    assert model.metadata["provenance"]["clip"] == "stomper.bvh"


def test_sample_with_no_model_uses_the_demo(tmp_path, no_torch_env):
    result = run_cli("sinmdm-run", "sample", "--out", str(tmp_path), "--frames", "64", "--steps", "4", "--json",
                     env=no_torch_env, check=True)
    assert len(json.loads(result.stdout)["files"]) == 1


@pytest.mark.parametrize(
    "args, message",
    [
        (["--frames", "0"], "--frames"),
        (["--frames", "-5"], "--frames"),
        (["--count", "0"], "--count"),
        (["--seconds", "-1"], "positive"),
        (["--frames", "200000"], "--force"),
        (["--steps", "0"], "--steps"),
        (["--sampler", "euler"], "unknown sampler"),
        (["--format", "fbx"], "unknown format"),
    ],
)
def test_bad_requests_exit_2_without_files(tiny_model, tmp_path, args, message):
    result = sample(tiny_model, tmp_path / "out", *args, check=False)
    assert result.returncode == 2 and message in result.stderr and "Traceback" not in result.stderr
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_damaged_foreign_and_mixed_models(tiny_model, tiny_run, tmp_path):
    damaged = tmp_path / "damaged.onnx"
    damaged.write_bytes(tiny_model.read_bytes()[:5000])
    result = sample(damaged, tmp_path / "o1", check=False)
    assert result.returncode == 2 and "damaged.onnx" in result.stderr

    foreign = tmp_path / "foreign.onnx"
    graph = onnx.helper.make_graph(
        [onnx.helper.make_node("Identity", ["x_t"], ["x0"])], "g",
        [onnx.helper.make_tensor_value_info("x_t", onnx.TensorProto.FLOAT, [1, 2])],
        [onnx.helper.make_tensor_value_info("x0", onnx.TensorProto.FLOAT, [1, 2])],
    )
    plain = onnx.helper.make_model(graph, opset_imports=[onnx.helper.make_opsetid("", 18)])
    plain.ir_version = 8
    onnx.save(plain, foreign)
    result = sample(foreign, tmp_path / "o2", check=False)
    assert result.returncode == 2 and "not a sinmdm model" in result.stderr

    other = tmp_path / "other" / "m.onnx"
    other.parent.mkdir()
    run_cli("sinmdm", "train", str(DEMO_CLIP), "--out", str(tmp_path / "run2"), "--steps", "2", "--seed", "9",
            "--width", "32", "--batch", "2", "--crop", "48", "--check-every", "0", check=True)
    run_cli("sinmdm", "export", str(tmp_path / "run2"), "--out", str(other), "-w", "64", check=True)
    result = run_cli("sinmdm-run", "sample", str(tiny_model), str(other.with_name("m_w64.onnx")),
                     "--out", str(tmp_path / "o3"))
    assert result.returncode == 2 and "another model" in result.stderr

    version = tmp_path / "future.onnx"
    model = onnx.load(tiny_model)
    for prop in model.metadata_props:
        if prop.key == "sinmdm":
            doc = json.loads(prop.value)
            doc["format_version"] = 99
            prop.value = json.dumps(doc)
    onnx.save(model, version)
    result = sample(version, tmp_path / "o4", check=False)
    assert result.returncode == 2 and "format 99" in result.stderr


def test_unwritable_output_dir(tiny_model, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    result = sample(tiny_model, blocker / "out", check=False)
    assert result.returncode == 2 and "Traceback" not in result.stderr


def test_edge_margin_is_the_middle_of_a_longer_sample():
    """margin k samples k extra frames at each end and cuts them: exactly the middle of a
    margin-0 sample (the paper's sampler) of frames + 2k, same seed, same noise."""
    from sinmdm.runtime.sampler import Guide, sample_features

    model = load_model()
    wide = sample_features(model, 96 + 16, SamplingOptions(count=2, seed=4, steps=6, margin=0))
    cut = sample_features(model, 96, SamplingOptions(count=2, seed=4, steps=6, margin=8))
    np.testing.assert_array_equal(cut, wide[:, 8:104])
    keep = np.zeros((model.features, 96))
    keep[:, :10] = 1.0
    reference = np.full((model.features, 96), 0.25)
    guided = sample_features(model, 96, SamplingOptions(seed=4, steps=6, margin=8), guide=Guide(reference=reference, keep=keep))
    np.testing.assert_allclose(guided[0, :10], 0.25, atol=1e-6)  # the guide moves with the margin
    assert not np.allclose(guided[0, 10:], 0.25)


def test_edge_margin_steadies_the_first_frames():
    """On the demo model the first and last frames' root height wobbles less with the margin."""
    model = load_model()
    _, height, _ = model.codec.layout.indices(("root",))
    wobble = {}
    for margin in (0, 8):
        features = generate(model, 200, SamplingOptions(count=8, seed=0, margin=margin)).features
        ends = np.abs(np.diff(features[:, :4, height], axis=1)).mean() + np.abs(np.diff(features[:, -4:, height], axis=1)).mean()
        middle = np.abs(np.diff(features[:, 50:150, height], axis=1)).mean()
        wobble[margin] = ends / middle
    assert wobble[8] < wobble[0]
