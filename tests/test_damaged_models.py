"""Damaged and foreign models, built by editing a copy of the demo model with `onnx`: each
is refused with a ModelError naming the file, before anything uses it (and the CLI says so
in one line, exit 2)."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path
from typing import Callable

import numpy as np
import pytest

onnx = pytest.importorskip("onnx")
from onnx import TensorProto, helper  # noqa: E402

from sinmdm.runtime.errors import ModelError, OptionError  # noqa: E402
from sinmdm.runtime.model import DEMO_MODEL, load_model  # noqa: E402
from sinmdm.runtime.model_format import METADATA_KEY  # noqa: E402

from .conftest import run_cli  # noqa: E402


@pytest.fixture(scope="module")
def demo_proto():
    return onnx.load(DEMO_MODEL)


def _metadata_entry(model):
    return next(p for p in model.metadata_props if p.key == METADATA_KEY)


def set_metadata_text(text: str) -> Callable:
    def edit(model) -> None:
        _metadata_entry(model).value = text
    return edit


def edit_document(change: Callable[[dict], object]) -> Callable:
    """An edit of the parsed metadata; `change` edits the dict in place or returns a replacement."""
    def edit(model) -> None:
        entry = _metadata_entry(model)
        document = json.loads(entry.value)
        replaced = change(document)
        entry.value = json.dumps(document if replaced is None else replaced)
    return edit


def set_key(*keys_and_value) -> Callable:
    *keys, value = keys_and_value

    def change(document: dict) -> None:
        for key in keys[:-1]:
            document = document[key]
        document[keys[-1]] = value
    return edit_document(change)


def edit_alphas(change: Callable[[list], list]) -> Callable:
    return edit_document(lambda d: d.update(alphas_cumprod=change(d["alphas_cumprod"])))


def rename_input(model) -> None:
    old = model.graph.input[0].name
    model.graph.input[0].name = "x"
    for node in model.graph.node:
        node.input[:] = ["x" if name == old else name for name in node.input]


def rename_output(model) -> None:
    model.graph.output[0].name = "out"
    model.graph.node[-1].output[0] = "out"


def append_to_output(op: str, make_inputs: Callable[[str], list[str]], attributes: dict | None = None,
                     initializers: tuple = ()) -> Callable:
    """The real graph with one node appended after its last one (the new x0)."""
    def edit(model) -> None:
        model.graph.node[-1].output[0] = "inner"
        model.graph.initializer.extend(initializers)
        model.graph.node.append(helper.make_node(op, make_inputs("inner"), ["x0"], **(attributes or {})))
        del model.graph.output[0].type.tensor_type.shape.dim[:]
    return edit


def identity_graph(model) -> None:
    """x0 = x_t, with the demo's inputs, outputs and metadata grafted on."""
    del model.graph.node[:]
    del model.graph.initializer[:]
    model.graph.node.append(helper.make_node("Identity", ["x_t"], ["x0"]))


def nested(depth: int) -> str:
    return '{"format":"sinmdm-denoiser","format_version":1,"codec":' + "[" * depth + "]" * depth + "}"


NAN_CONSTANT = helper.make_tensor("nan", TensorProto.FLOAT, [], [math.nan])
CASES: dict[str, Callable] = {
    "metadata a list": set_metadata_text("[1, 2]"),
    "metadata a string": set_metadata_text('"sinmdm"'),
    "metadata null": set_metadata_text("null"),
    "metadata not JSON": set_metadata_text("{not json"),
    "metadata nested 100,000 deep": set_metadata_text(nested(100_000)),
    "window a string": set_key("window", "64"),
    "window zero": set_key("window", 0),
    "window a bool": set_key("window", True),
    "receptive field a string": set_key("receptive_field", "23"),
    "receptive field negative": set_key("receptive_field", -5),
    "trained window huge": set_key("trained_window", 10**12),
    "alphas a string": set_key("alphas_cumprod", "0.9"),
    "alphas a dict": set_key("alphas_cumprod", {"0": 0.9}),
    "alphas with NaN": edit_alphas(lambda a: a[:5] + [math.nan] + a[6:]),
    "alphas negative": edit_alphas(lambda a: a[:-1] + [-0.001]),
    "alphas above 1": edit_alphas(lambda a: [1.5] + a[1:]),
    "alphas not decreasing": edit_alphas(lambda a: a[:10] + [a[9]] + a[11:]),
    "ten alphas": edit_alphas(lambda a: a[::100]),
    "alphas of strings": edit_alphas(lambda a: [str(v) for v in a]),
    "schedule timesteps a string": set_key("schedule", "timesteps", "1000"),
    "codec a list": set_key("codec", []),
    "codec scale 0": set_key("codec", "scale", 0),
    "codec scale NaN": set_key("codec", "scale", math.nan),
    "codec scale infinite": set_key("codec", "scale", math.inf),
    "codec fps negative": set_key("codec", "fps", -30),
    "codec without skeleton": edit_document(lambda d: d["codec"].pop("skeleton") and None),
    "codec names not strings": edit_document(lambda d: d["codec"]["skeleton"].update(names=list(range(19)))),
    "codec unknown contact joint": set_key("codec", "contact_joints", ["Tail"]),
    "codec rest translations short": set_key("codec", "rest_translations", [[0.0, 0.0, 0.0]]),
    "codec up axis 7": set_key("codec", "up_axis", 7),
    "sampling defaults a string": set_key("sampling_defaults", "fast"),
    "sampling steps a string": set_key("sampling_defaults", {"steps": "50", "hop": 8}),
    "sampling hop zero": set_key("sampling_defaults", {"steps": 50, "hop": 0}),
    "sampling smooth negative": set_key("sampling_defaults", {"steps": 50, "hop": 8, "smooth": -1.0}),
    "sampling smooth too wide": set_key("sampling_defaults", {"steps": 50, "hop": 8, "smooth": 50}),
    "velocity unit unknown": set_key("velocity_unit", "minute"),
    "provenance a string": set_key("provenance", "trained by me"),
    "model id a number": set_key("model_id", 7),
    "start position of 3": set_key("start_position", [0.0, 0.0, 0.0]),
    "inputs not (x_t, t)": rename_input,
    "output not named x0": rename_output,
    "window 32 on a 64-frame graph": set_key("window", 32),
    "features 118 on a 119-feature graph": edit_document(
        lambda d: (d["codec"]["contact_joints"].pop(), d["codec"].pop("layout")) and None),
    "identity graph with grafted metadata": identity_graph,
    "output of the wrong shape": append_to_output("Concat", lambda x: [x, x], {"axis": 2}),
    "output NaN": append_to_output("Mul", lambda x: [x, "nan"], initializers=(NAN_CONSTANT,)),
}


def damaged(demo_proto, tmp_path: Path, case: str) -> Path:
    model = copy.deepcopy(demo_proto)
    CASES[case](model)
    path = tmp_path / "damaged_w64.onnx"
    onnx.save(model, path)
    return path


@pytest.mark.parametrize("case", list(CASES))
def test_damaged_model_is_refused_naming_the_file(demo_proto, tmp_path, case):
    path = damaged(demo_proto, tmp_path, case)
    with pytest.raises(ModelError) as info:
        load_model(path)
    message = str(info.value)
    assert str(path) in message and "\n" not in message and len(message) < 400


def test_truncated_file_is_refused(tmp_path):
    path = tmp_path / "cut_w64.onnx"
    path.write_bytes(DEMO_MODEL.read_bytes()[:100_000])
    with pytest.raises(ModelError, match=f"^{path} is not a readable ONNX model"):
        load_model(path)


def test_the_demo_model_itself_passes_every_check():
    model = load_model()
    assert model.windows == [64] and model.features == 119 and len(model.alphas_cumprod) == 1000


@pytest.mark.parametrize("case", ["metadata nested 100,000 deep", "alphas above 1", "identity graph with grafted metadata",
                                  "window 32 on a 64-frame graph"])
def test_cli_refuses_a_damaged_model_in_one_line(demo_proto, tmp_path, case):
    path = damaged(demo_proto, tmp_path, case)
    result = run_cli("sinmdm-run", "sample", str(path), "--out", str(tmp_path / "out"), "--frames", "64")
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1 and str(path) in lines[0], result.stderr
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


@pytest.mark.parametrize("threads", [0, -1, 257, 100_000, True, 2.5, "4"])
def test_threads_are_bounded(threads):
    with pytest.raises(OptionError) as info:
        load_model(threads=threads)
    assert info.value.option == "threads"


def test_threads_in_range_load():
    model = load_model(threads=1)
    x_t = np.zeros((1, model.features, 64), dtype=np.float32)
    assert model.denoisers[64](x_t, np.array([10.0])).shape == x_t.shape
