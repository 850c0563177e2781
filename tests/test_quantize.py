"""`sinmdm quantize`: a mixed-precision copy of each window (int8 convolutions for every step
but the last, the float32 graph at t = 0), written only after a quality check
against the clip, runs in the runtime unchanged and refuses what it cannot trust."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from sinmdm.export import quantize
from sinmdm.runtime import SamplingOptions, generate, load_model
from sinmdm.runtime.errors import SinMDMError
from sinmdm.runtime.model import DEMO_MODEL

from .conftest import DEMO_CLIP, real_clip, run_cli
from .test_runtimes import ort_node  # noqa: F401 (the fixture)


def _copy_demo(directory: Path) -> Path:
    for source in (DEMO_MODEL, DEMO_MODEL.with_suffix(".json")):
        shutil.copy(source, directory / source.name)
    return directory / DEMO_MODEL.name


@pytest.fixture(scope="module")
def mixed(tmp_path_factory) -> tuple[Path, Path, dict]:
    directory = tmp_path_factory.mktemp("quantized")
    source = _copy_demo(directory)
    checked = quantize.quantize_model([source], DEMO_CLIP, samples=4, threads=2)
    return source, directory / quantize.mixed_name(source), checked


def test_mixed_copy_carries_its_precision_and_check(mixed):
    source, target, checked = mixed
    assert checked["outputs"] == [str(target)] and target.with_suffix(".json").is_file()
    model = load_model(target)
    assert model.metadata["precision"] == {"int8_above_t": 0}
    record = model.metadata["provenance"]["quantized"]
    assert record["source"] == source.name and record["samples"] == 4
    assert set(record["float32"]) == set(record["mixed"]) >= {"coverage", "global_diversity", "jitter_ratio", "balance"}
    assert json.loads(target.with_suffix(".json").read_text())["precision"] == {"int8_above_t": 0}


def test_the_last_steps_run_the_float32_graph_and_the_noisy_ones_int8(mixed):
    source, target, _ = mixed
    float32, int8 = load_model(source).denoisers[64], load_model(target).denoisers[64]
    x = np.random.default_rng(3).standard_normal((3, load_model(source).features, 64)).astype(np.float32)
    for t in (0.0,):  # float32 branch: the same graph, the same numbers
        steps = np.full(3, t, dtype=np.float32)
        np.testing.assert_allclose(int8(x, steps), float32(x, steps), atol=1e-5)
    for t in (1.0, 20.0, 500.0, 999.0):  # int8 branch: close, not equal
        steps = np.full(3, t, dtype=np.float32)
        a, b = float32(x, steps), int8(x, steps)
        error = np.abs(a - b).mean() / np.abs(a).mean()
        assert 0 < error < 0.03, (t, error)


def test_mixed_model_samples_like_the_float32_one(mixed):
    source, target, _ = mixed
    options = SamplingOptions(count=2, seed=5)
    a, b = generate(load_model(source), 120, options), generate(load_model(target), 120, options)
    assert a.features.shape == b.features.shape
    # the float32 branch finishes both: the motions differ only by what the int8 steps moved
    spread = np.abs(a.features).mean()
    assert np.abs(a.features - b.features).mean() < 0.1 * spread
    again = generate(load_model(target), 120, options)  # deterministic
    assert np.array_equal(again.features, b.features)


def test_quantize_refuses_a_mixed_model_and_an_existing_output(mixed, tmp_path):
    source, target, _ = mixed
    with pytest.raises(SinMDMError, match="already mixed-precision"):
        quantize.quantize_model([target], DEMO_CLIP, samples=2)
    result = run_cli("sinmdm", "quantize", str(source), "--clip", str(DEMO_CLIP), "--samples", "2")
    assert result.returncode == 2 and "exists" in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_quantize_refuses_another_clip(tmp_path):
    source = _copy_demo(tmp_path)
    result = run_cli("sinmdm", "quantize", str(source), "--clip", str(real_clip("Xia_proud.bvh")))
    assert result.returncode == 2 and "is not the clip this model learned" in result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["stomper_w64.json", "stomper_w64.onnx"]


@pytest.mark.slow
def test_a_copy_that_loses_quality_is_not_written(tmp_path, monkeypatch):
    source = _copy_demo(tmp_path)
    monkeypatch.setattr(quantize, "JITTER_TOLERANCE", -0.5)  # any jitter at all counts as a loss
    with pytest.raises(SinMDMError, match="loses quality.*nothing written"):
        quantize.quantize_model([source], DEMO_CLIP, samples=2, threads=2)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["stomper_w64.json", "stomper_w64.onnx"]


@pytest.mark.slow
def test_quantize_cli_prints_both_graphs_scores(tmp_path):
    source = _copy_demo(tmp_path)
    out = tmp_path / "int8"
    out.mkdir()
    result = run_cli("sinmdm", "quantize", str(source), "--clip", str(DEMO_CLIP), "--samples", "2", "--threads", "2",
                     "--out", str(out), check=True)
    shown = result.stdout + result.stderr
    assert "float32" in shown and "mixed" in shown and "written" in shown
    assert sorted(p.name for p in out.iterdir()) == ["stomper_w64_int8.json", "stomper_w64_int8.onnx"]
    sampled = run_cli("sinmdm-run", "sample", str(out / "stomper_w64_int8.onnx"), "--frames", "90",
                      "--out", str(tmp_path / "samples"), check=True)
    assert (tmp_path / "samples" / "sample_0000.bvh").is_file(), sampled.stdout


def test_tract_runs_the_mixed_graph_as_onnxruntime_does(mixed):
    """tract reads the If and QLinearConv graph; OpenVINO does not (its ONNX frontend fails on
    QLinearConv at opset 18: the float32 file is the one for OpenVINO, README)."""
    pytest.importorskip("tract", reason="tract is not installed (the dev extra)")
    from .test_runtimes import TractDenoiser

    _, target, _ = mixed
    float32 = load_model(target).denoisers[64]
    tract = TractDenoiser(target, 64)
    x = np.random.default_rng(4).standard_normal((2, load_model(target).features, 64)).astype(np.float32)
    for t in (0.0, 10.0, 500.0, 999.0):
        steps = np.full(2, t, dtype=np.float32)
        assert np.abs(tract(x, steps) - float32(x, steps)).max() <= 1e-4, t


def test_onnxruntime_node_runs_the_mixed_graph(mixed, ort_node, tmp_path):
    from .test_runtimes import _onnxruntime, _worst, run_in_ort_node

    _, target, _ = mixed
    features = load_model(target).features
    rng = np.random.default_rng(6)
    cases = [(rng.standard_normal((2, features, 64)).astype(np.float32), np.full(2, t, dtype=np.float32))
             for t in (0.0, 10.0, 500.0, 999.0)]  # every item of a call at one step, as the sampler sends them
    assert _worst(run_in_ort_node(ort_node, target, cases, tmp_path), _onnxruntime(target, cases)) <= 1e-5
