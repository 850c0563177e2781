"""Export of a real (tiny) trained run: graph rules, parity, self-describing metadata."""

from __future__ import annotations

import json
import shutil

import numpy as np
import onnx
import onnxruntime as ort
import pytest
import torch

from sinmdm.export.onnx_export import ALLOWED_OPS, weights_id
from sinmdm.runtime.model_format import METADATA_KEY, decode_metadata, sidecar_path
from sinmdm.runtime.schedule import cosine_alphas_cumprod
from sinmdm.train.trainer import load_trained_model

from .conftest import run_cli

FORBIDDEN = {"Einsum", "GroupNormalization", "InstanceNormalization", "Dropout", "If", "Loop", "Scan",
             "RandomNormal", "RandomUniform", "RandomNormalLike", "RandomUniformLike", "Bernoulli"}


def test_graph_follows_the_rules(tiny_model):
    model = onnx.load(tiny_model)
    onnx.checker.check_model(model, full_check=True)
    ops = {node.op_type for node in model.graph.node}
    assert ops <= ALLOWED_OPS and not ops & FORBIDDEN
    assert model.opset_import[0].version == 18 and model.ir_version <= 9
    inputs = {i.name: i.type.tensor_type for i in model.graph.input}
    assert set(inputs) == {"x_t", "t"}
    assert all(t.elem_type == onnx.TensorProto.FLOAT for t in inputs.values())
    dims = [d.dim_value or d.dim_param for d in inputs["x_t"].shape.dim]
    assert dims[0] == "batch" and dims[2] == 48
    for init in model.graph.initializer:
        assert init.data_type in (onnx.TensorProto.FLOAT, onnx.TensorProto.INT64)


def test_metadata_is_self_describing(tiny_model, tiny_run):
    session = ort.InferenceSession(str(tiny_model), providers=["CPUExecutionProvider"])
    meta = decode_metadata(session.get_modelmeta().custom_metadata_map[METADATA_KEY], str(tiny_model))
    assert meta["format_version"] == 1
    assert meta["codec"]["skeleton"]["names"][0] == "Hips"
    assert meta["codec"]["contact_joints"] == ["LeftToe", "RightToe"]
    assert meta["codec"]["scale"] == 0.01 and meta["codec"]["fps"] == 30.0
    assert meta["codec"]["layout"][-1]["kind"] == "root"
    np.testing.assert_allclose(meta["alphas_cumprod"], cosine_alphas_cumprod())
    assert meta["window"] == 48 and meta["receptive_field"] == 23
    provenance = meta["provenance"]
    assert provenance["clip"] == "stomper.bvh" and len(provenance["clip_sha256"]) == 64
    assert provenance["preset"] == "cpu" and provenance["steps"] == 10 and provenance["sinmdm_version"]
    model, _ = load_trained_model(tiny_run)
    assert meta["model_id"] == weights_id(model)


def test_parity_with_torch_at_several_t_and_batches(tiny_model, tiny_run):
    model, config = load_trained_model(tiny_run)
    session = ort.InferenceSession(str(tiny_model), providers=["CPUExecutionProvider"])
    rng = np.random.default_rng(0)
    for batch, t in [(1, 0), (3, 500), (5, 999)]:
        x = rng.standard_normal((batch, config["model"]["features"], 48)).astype(np.float32)
        steps = np.full(batch, t, dtype=np.float32)
        with torch.no_grad():
            expected = model(torch.from_numpy(x), torch.from_numpy(steps)).numpy()
        got = session.run(["x0"], {"x_t": x, "t": steps})[0]
        assert np.abs(expected - got).max() < 1e-4


def test_opset_17_and_several_windows(tiny_run, tmp_path):
    result = run_cli("sinmdm", "export", str(tiny_run), "--out", str(tmp_path / "m.onnx"), "-w", "48", "-w", "96",
                     "--opset", "17", "--json", check=True)
    exported = json.loads(result.stdout)
    assert [e["window"] for e in exported] == [48, 96]
    assert all(e["max_abs_diff"] < 1e-4 and e["opset"] == 17 for e in exported)
    assert "differs from the training length" in result.stderr
    assert onnx.load(tmp_path / "m_w96.onnx").opset_import[0].version == 17


def test_refuses_existing_output(tiny_run, tiny_model):
    before = tiny_model.read_bytes()
    result = run_cli("sinmdm", "export", str(tiny_run), "--out", str(tiny_model.with_name("tiny.onnx")))
    assert result.returncode == 2 and "--force" in result.stderr
    assert tiny_model.read_bytes() == before


@pytest.mark.parametrize("window, message", [("10", "receptive field"), ("0", "receptive field")])
def test_refuses_bad_window(tiny_run, tmp_path, window, message):
    result = run_cli("sinmdm", "export", str(tiny_run), "--out", str(tmp_path / "m.onnx"), "-w", window)
    assert result.returncode == 2 and message in result.stderr
    assert list(tmp_path.iterdir()) == []


def test_refuses_unfinished_run(tiny_run, tmp_path):
    unfinished = tmp_path / "unfinished"
    shutil.copytree(tiny_run, unfinished)
    config = json.loads((unfinished / "config.json").read_text())
    config.update(steps=100, finished=False)
    (unfinished / "config.json").write_text(json.dumps(config))
    result = run_cli("sinmdm", "export", str(unfinished), "--out", str(tmp_path / "m.onnx"))
    assert result.returncode == 2 and "finished" in result.stderr
    assert not (tmp_path / "m_w48.onnx").exists()


def test_refuses_missing_run_and_unwritable_path(tmp_path, tiny_run):
    result = run_cli("sinmdm", "export", str(tmp_path / "nope"), "--out", str(tmp_path / "m.onnx"))
    assert result.returncode == 2 and "not a training run" in result.stderr
    (tmp_path / "file").write_text("")
    result = run_cli("sinmdm", "export", str(tiny_run), "--out", str(tmp_path / "file" / "m.onnx"))
    assert result.returncode == 2 and "cannot create output directory" in result.stderr


def test_graph_has_no_intermediate_shapes_and_a_sidecar(tiny_model):
    """Only inputs and outputs are annotated (tract cannot pin the batch otherwise), and the
    metadata lies beside the graph too, the same document, written with it."""
    model = onnx.load(tiny_model)
    assert len(model.graph.value_info) == 0
    for value in list(model.graph.input) + list(model.graph.output):
        assert value.type.tensor_type.shape.dim[0].dim_param == "batch"
    metadata = next(p.value for p in model.metadata_props if p.key == METADATA_KEY)
    assert sidecar_path(tiny_model) == tiny_model.with_name("tiny_w48.json")
    assert sidecar_path(tiny_model).read_text(encoding="utf-8") == metadata
    assert sorted(p.name for p in tiny_model.parent.iterdir()) == ["tiny_w48.json", "tiny_w48.onnx"]


def test_demo_model_has_no_intermediate_shapes_and_its_sidecar():
    from sinmdm.runtime.model import DEMO_MODEL

    model = onnx.load(DEMO_MODEL)
    assert len(model.graph.value_info) == 0
    metadata = next(p.value for p in model.metadata_props if p.key == METADATA_KEY)
    assert sidecar_path(DEMO_MODEL).read_text(encoding="utf-8") == metadata


def test_existing_sidecar_refuses_the_export(tiny_run, tmp_path):
    (tmp_path / "m_w48.json").write_text("{}")
    result = run_cli("sinmdm", "export", str(tiny_run), "--out", str(tmp_path / "m.onnx"))
    assert result.returncode == 2 and "m_w48.json exists" in result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m_w48.json"]
