"""The exported graph in other runtimes than onnxruntime (Python): OpenVINO at full precision,
tract with a symbolic and with a pinned batch, and onnxruntime-node give onnxruntime's outputs
on the same inputs, and a whole sampled motion through OpenVINO or tract decodes to the same
joint positions. Each runtime's tests skip, saying what is missing, where it is not installed."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import pytest

from sinmdm.runtime import SamplingOptions, load_model
from sinmdm.runtime.animation import global_positions
from sinmdm.runtime.model import DEMO_MODEL
from sinmdm.runtime.model_format import INPUT_NAMES, OUTPUT_NAME
from sinmdm.runtime.sampler import sample_features

OUTPUT_TOLERANCE = 1e-5  # max abs difference from onnxruntime (Python) on one call
POSITION_TOLERANCE = 1e-4  # joint positions of a whole sampled motion, as a fraction of the figure's height
TIMESTEPS = ((0, 999), (1, 500), (10, 250), (100, 750))  # one batch of 2 per pair
MOTION_FRAMES, MOTION_SEED = 200, 0
ORT_NODE_VARIABLE = "SINMDM_ORT_NODE"

# Reads the cases written by _write_cases, runs each through onnxruntime-node, writes x0 (float32, raw).
ORT_NODE_SCRIPT = """
const fs = require("fs");
const ort = require("onnxruntime-node");
const [model, dir] = process.argv.slice(2);
const floats = (name) => new Float32Array(new Uint8Array(fs.readFileSync(`${dir}/${name}`)).buffer);
(async () => {
  const { cases, batch, features, window } = JSON.parse(fs.readFileSync(`${dir}/cases.json`, "utf8"));
  const x = floats("x_t.bin"), t = floats("t.bin"), size = batch * features * window;
  const session = await ort.InferenceSession.create(model);
  const out = new Float32Array(cases * size);
  for (let i = 0; i < cases; i++) {
    const feeds = {
      x_t: new ort.Tensor("float32", x.slice(i * size, (i + 1) * size), [batch, features, window]),
      t: new ort.Tensor("float32", t.slice(i * batch, (i + 1) * batch), [batch]),
    };
    out.set((await session.run(feeds)).x0.data, i * size);
  }
  fs.writeFileSync(`${dir}/x0.bin`, Buffer.from(out.buffer));
})().catch((error) => { console.error(error.message); process.exit(1); });
"""


# ------------------------------------------------------------------ the runtimes, as denoisers


def _import(name: str):
    return pytest.importorskip(name, reason=f"{name} is not installed (pip install {name}, or the dev extra)")


@dataclasses.dataclass
class OpenVinoDenoiser:
    """The graph compiled by OpenVINO for its CPU plugin at float32: its default precision
    may be bf16 on CPUs that have it (measured 1e-2 off)."""

    path: Path
    window: int

    def __post_init__(self) -> None:
        openvino = _import("openvino")
        core = openvino.Core()
        self.compiled = core.compile_model(core.read_model(str(self.path)), "CPU", {"INFERENCE_PRECISION_HINT": "f32"})

    def __call__(self, x_t: np.ndarray, t: np.ndarray) -> np.ndarray:
        return np.asarray(self.compiled([x_t.astype(np.float32), t.astype(np.float32)])[0])


@dataclasses.dataclass
class TractDenoiser:
    """The graph run by tract: with the batch left symbolic, or `pinned` (one plan per batch
    size, its inputs' shapes fixed, which needs a graph without intermediate shape annotations)."""

    path: Path
    window: int
    pinned: bool = False

    def __post_init__(self) -> None:
        self.tract = _import("tract")
        self.plans: dict[int | None, object] = {}

    def plan(self, batch: int):
        key = batch if self.pinned else None
        if key not in self.plans:
            model = self.tract.onnx().load(str(self.path))
            if self.pinned:
                features, window = _shape(self.path)
                model.set_input_fact(0, f"{batch},{features},{window},f32")
                model.set_input_fact(1, f"{batch},f32")
            self.plans[key] = model.into_model().into_runnable()
        return self.plans[key]

    def __call__(self, x_t: np.ndarray, t: np.ndarray) -> np.ndarray:
        outputs = self.plan(len(x_t)).run([x_t.astype(np.float32), t.astype(np.float32)])
        return outputs[0].to_numpy()


RUNTIMES = {
    "openvino": OpenVinoDenoiser,
    "tract": TractDenoiser,
    "tract-pinned": lambda path, window: TractDenoiser(path, window, pinned=True),
}


# ------------------------------------------------------------------ inputs and references


def _shape(path: Path) -> tuple[int, int]:
    """(features, window) of the graph's input x_t."""
    dims = onnx.load(str(path), load_external_data=False).graph.input[0].type.tensor_type.shape.dim
    return dims[1].dim_value, dims[2].dim_value


def _cases(path: Path) -> list[tuple[np.ndarray, np.ndarray]]:
    features, window = _shape(path)
    rng = np.random.default_rng(0)
    return [(rng.standard_normal((2, features, window)).astype(np.float32), np.array(pair, dtype=np.float32))
            for pair in TIMESTEPS]


def _onnxruntime(path: Path, cases) -> list[np.ndarray]:
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    return [session.run([OUTPUT_NAME], {INPUT_NAMES[0]: x, INPUT_NAMES[1]: t})[0] for x, t in cases]


def _worst(got: list[np.ndarray], expected: list[np.ndarray]) -> float:
    assert [g.shape for g in got] == [e.shape for e in expected]
    return max(float(np.abs(g - e).max()) for g, e in zip(got, expected))


@pytest.fixture(scope="module")
def demo_reference():
    cases = _cases(DEMO_MODEL)
    return cases, _onnxruntime(DEMO_MODEL, cases)


# ------------------------------------------------------------------ one call: the same outputs


@pytest.mark.parametrize("runtime", sorted(RUNTIMES))
def test_runtime_gives_onnxruntimes_outputs(runtime, demo_reference):
    cases, expected = demo_reference
    denoiser = RUNTIMES[runtime](DEMO_MODEL, _shape(DEMO_MODEL)[1])
    got = [denoiser(x, t) for x, t in cases]
    assert _worst(got, expected) <= OUTPUT_TOLERANCE


def test_freshly_exported_model_runs_in_tract_at_a_fixed_batch(tiny_model):
    cases = _cases(tiny_model)
    denoiser = TractDenoiser(tiny_model, _shape(tiny_model)[1], pinned=True)
    assert _worst([denoiser(x, t) for x, t in cases], _onnxruntime(tiny_model, cases)) <= OUTPUT_TOLERANCE


@pytest.fixture
def ort_node() -> Path:
    """The npm prefix where onnxruntime-node is installed (scripts/ci_runtimes.sh)."""
    if shutil.which("node") is None:
        pytest.skip("node is not installed")
    prefix = os.environ.get(ORT_NODE_VARIABLE)
    if not prefix:
        pytest.skip(f"{ORT_NODE_VARIABLE} is not set (an npm prefix with onnxruntime-node; scripts/ci_runtimes.sh)")
    if not (Path(prefix) / "node_modules" / "onnxruntime-node").is_dir():
        pytest.skip(f"onnxruntime-node is not installed under {ORT_NODE_VARIABLE}={prefix}")
    return Path(prefix)


def _write_cases(directory: Path, cases) -> None:
    x, t = cases[0]
    (directory / "cases.json").write_text(json.dumps(
        {"cases": len(cases), "batch": x.shape[0], "features": x.shape[1], "window": x.shape[2]}))
    (directory / "x_t.bin").write_bytes(np.stack([x for x, _ in cases]).astype("<f4").tobytes())
    (directory / "t.bin").write_bytes(np.stack([t for _, t in cases]).astype("<f4").tobytes())


def run_in_ort_node(ort_node: Path, model: Path, cases, directory: Path) -> list[np.ndarray]:
    """x0 of each case, from `model` run by onnxruntime-node (ORT_NODE_SCRIPT) in `directory`."""
    _write_cases(directory, cases)
    (directory / "run.js").write_text(ORT_NODE_SCRIPT)
    env = dict(os.environ, NODE_PATH=str(ort_node / "node_modules"))
    result = subprocess.run(["node", str(directory / "run.js"), str(model), str(directory)],
                            capture_output=True, text=True, env=env, timeout=300)
    assert result.returncode == 0, result.stderr
    x, _ = cases[0]
    return list(np.frombuffer((directory / "x0.bin").read_bytes(), dtype="<f4").reshape((len(cases), *x.shape)))


def test_onnxruntime_node_gives_onnxruntimes_outputs(ort_node, demo_reference, tmp_path):
    cases, expected = demo_reference
    assert _worst(run_in_ort_node(ort_node, DEMO_MODEL, cases, tmp_path), expected) <= OUTPUT_TOLERANCE


# ------------------------------------------------------------------ a whole motion: the same joints


def _joint_positions(model, seed: int) -> np.ndarray:
    """(frames, joints, 3) metres of one sampled motion (default sampler), decoded without cleanup."""
    features = sample_features(model, MOTION_FRAMES, SamplingOptions(seed=seed))[0]
    return global_positions(model.codec.decode(features, model.start_position)) * model.codec.scale


@pytest.fixture(scope="module")
def demo_model():
    return load_model(DEMO_MODEL, threads=1)


@pytest.fixture(scope="module")
def demo_motion(demo_model) -> np.ndarray:
    return _joint_positions(demo_model, MOTION_SEED)


@pytest.mark.parametrize("runtime", ["openvino", "tract-pinned"])
def test_sampled_motion_matches_onnxruntime(runtime, demo_model, demo_motion):
    denoisers = {w: RUNTIMES[runtime](d.path, w) for w, d in demo_model.denoisers.items()}
    positions = _joint_positions(dataclasses.replace(demo_model, denoisers=denoisers), MOTION_SEED)
    assert positions.shape == demo_motion.shape
    assert np.abs(positions - demo_motion).max() <= POSITION_TOLERANCE * demo_model.codec.size
