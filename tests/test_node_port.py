"""Golden vectors (`sinmdm-run vectors`) and the Node reference port (ports/node) that
replays them: the vectors are the real sampler's own chain, bit for bit, and the port
reproduces the features and joint positions from them within 1e-4."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from sinmdm.runtime.animation import global_positions
from sinmdm.runtime.model import DEMO_MODEL, load_model
from sinmdm.runtime.options import SamplingOptions
from sinmdm.runtime.sampler import WindowedDenoiser, sample_features
from sinmdm.runtime.schedule import Schedule
from sinmdm.runtime.smoothing import smooth_frames
from sinmdm.runtime.vectors import read_array

from .conftest import ROOT, call_cli

CHECK = ROOT / "ports" / "node" / "check.js"
TOLERANCE = 1e-4
# (options of `sinmdm-run vectors`, what sample_features gets for them)
CASES = {
    "few-steps": (["--frames", "160", "--steps", "4", "--seed", "3", "--smooth", "1"], dict(frames=160, steps=4, seed=3, smooth=1.0)),
    "default-steps": (["--frames", "160"], dict(frames=160)),
    "loop-ddim": (["--frames", "100", "--loop", "--hop", "20", "--sampler", "ddim", "--eta", "0.5", "--steps", "6",
                   "--smooth", "1.5"], dict(frames=100, loop=True, hop=20, sampler="ddim", eta=0.5, steps=6, smooth=1.5)),
}


@pytest.fixture(scope="module")
def model():
    return load_model(DEMO_MODEL, threads=1)


@pytest.fixture(scope="module")
def vectors(tmp_path_factory):
    """The vectors of every case, written once by the command."""
    written = {}
    for name, (args, _) in CASES.items():
        out = tmp_path_factory.mktemp("vectors") / name
        call_cli("sinmdm-run", "vectors", str(DEMO_MODEL), "--out", str(out), "--threads", "1", *args, check=True)
        written[name] = out
    return written


def manifest_of(directory: Path) -> dict:
    return json.loads((directory / "manifest.json").read_text())


def expected_options(model, case: dict) -> tuple[int, bool, SamplingOptions]:
    case = dict(case)
    frames, loop = case.pop("frames"), case.pop("loop", False)
    return frames, loop, SamplingOptions(**case).resolve(model, frames)


# ------------------------------------------------------------------ the vectors (Python only)

@pytest.mark.parametrize("name", list(CASES))
def test_the_vectors_are_the_samplers_own_chain_bit_for_bit(model, vectors, name):
    directory, document = vectors[name], manifest_of(vectors[name])
    frames, loop, options = expected_options(model, CASES[name][1])
    features = sample_features(model, frames, options, loop=loop)[0]
    arrays = {key: read_array(directory, document, key) for key in document["arrays"]}
    np.testing.assert_array_equal(arrays["features"], features)

    # the manifest: the model, the options as resolved, the windows and schedule the sampler used
    assert document["model"]["sha256"] == hashlib.sha256(DEMO_MODEL.read_bytes()).hexdigest()
    assert json.loads((directory / "metadata.json").read_text()) == model.metadata
    margin = 0 if loop else options.margin
    denoise = WindowedDenoiser(model, frames + 2 * margin, options.hop, loop=loop)
    schedule = Schedule.from_alphas_cumprod(model.alphas_cumprod, options.steps)
    assert document["options"] == {"frames": frames, "seed": options.seed, "sampler": options.sampler,
                                   "steps": options.steps, "eta": options.eta, "hop": denoise.hop,
                                   "margin": margin, "loop": loop, "smooth": options.smooth}
    assert document["window_starts"] == denoise.starts.tolist() and document["length"] == denoise.frames
    assert document["schedule"]["timesteps"] == schedule.timesteps.tolist()
    assert document["denoiser_timesteps"] == schedule.timesteps[::-1].tolist()
    c1, c2, log_var = schedule.posterior()
    assert document["schedule"]["c1"] == c1.tolist() and document["schedule"]["log_variance"] == log_var.tolist()

    # shapes, and every array's place in the chain
    F, L, S = model.features, denoise.frames, len(schedule.timesteps)
    joints = model.codec.skeleton.num_joints
    shapes = {"x_T": (F, L), "noise": (S - 1, F, L), "x_t": (S, F, L), "x0_hat": (S, F, L), "x_0": (F, L),
              "features": (frames, F), "smoothed": (frames, F), "local_rotations": (frames, joints, 3, 3),
              "local_translations": (frames, joints, 3), "positions": (frames, joints, 3)}
    assert {key: tuple(a.shape) for key, a in arrays.items()} == shapes
    assert all((directory / f"{key}.f32").stat().st_size == 4 * a.size for key, a in arrays.items())
    normals = np.random.default_rng(options.seed).standard_normal(F * L * S)
    np.testing.assert_array_equal(arrays["x_T"], normals[: F * L].reshape(F, L).astype(np.float32))
    np.testing.assert_array_equal(arrays["noise"], normals[F * L :].reshape(S - 1, F, L).astype(np.float32))
    np.testing.assert_array_equal(arrays["x_t"][0], arrays["x_T"])
    for k in range(S):
        step, noise = S - 1 - k, (arrays["noise"][k] if k < S - 1 else None)
        if options.sampler == "ddpm":
            after = schedule.ddpm_step(step, arrays["x_t"][k], arrays["x0_hat"][k], noise)
        else:
            after = schedule.ddim_step(step, arrays["x_t"][k], arrays["x0_hat"][k], options.eta, noise)
        np.testing.assert_array_equal(after, arrays["x_t"][k + 1] if k < S - 1 else arrays["x_0"])
    np.testing.assert_array_equal(arrays["x_0"][:, margin : margin + frames].T, arrays["features"])
    smoothed = smooth_frames(features[None], options.smooth, wrap=loop)[0]
    np.testing.assert_array_equal(arrays["smoothed"], smoothed)
    assert (options.smooth > 0) == (not np.array_equal(smoothed, features))
    animation = model.codec.decode(smoothed, model.start_position)
    np.testing.assert_array_equal(arrays["positions"], global_positions(animation).astype(np.float32))
    np.testing.assert_array_equal(arrays["local_rotations"], animation.rotations.astype(np.float32))


def test_vectors_refuse_bad_arguments_with_one_line(tmp_path):
    model = str(DEMO_MODEL)
    full = tmp_path / "full"
    full.mkdir()
    (full / "keep.txt").write_text("mine")
    a_file = tmp_path / "file"
    a_file.write_text("x")
    cases = [
        ([model, "--out", str(full)], "not empty"),
        ([model, "--out", str(a_file)], "not a directory"),
        ([model, "--out", str(tmp_path / "a"), "--frames", "0"], "--frames"),
        ([model, "--out", str(tmp_path / "b"), "--steps", "0"], "--steps"),
        ([model, "--out", str(tmp_path / "c"), "--steps", "1001"], "--steps"),
        ([model, "--out", str(tmp_path / "d"), "--hop", "65"], "--hop"),
        ([model, "--out", str(tmp_path / "e"), "--sampler", "euler"], "--sampler"),
        ([model, "--out", str(tmp_path / "f"), "--frames", "20", "--loop"], "loop"),
        ([str(tmp_path / "missing.onnx"), "--out", str(tmp_path / "g")], "does not exist"),
        ([model, "--out", str(tmp_path / "h"), "--frames", "100000", "--steps", "1000"], "GB"),
    ]
    for args, words in cases:
        result = call_cli("sinmdm-run", "vectors", *args)
        assert result.returncode == 2, (args, result.stderr)
        assert words in result.stderr and result.stderr.count("\n") == 1, (args, result.stderr)
        assert "Traceback" not in result.stderr
    assert sorted(p.name for p in full.iterdir()) == ["keep.txt"]
    assert not any((tmp_path / name).exists() for name in "abcdefgh")
    # --force writes beside what is there
    call_cli("sinmdm-run", "vectors", model, "--out", str(full), "--steps", "2", "--frames", "30", "--force", check=True)
    assert (full / "keep.txt").read_text() == "mine" and manifest_of(full)["options"]["steps"] == 2


# ------------------------------------------------------------------ the Node port

def node_environment() -> dict:
    """node and onnxruntime-node, or skip saying which is missing."""
    if shutil.which("node") is None:
        pytest.skip("node is not installed: the Node port is not checked")
    prefix = os.environ.get("SINMDM_ORT_NODE")
    if not prefix:
        pytest.skip("SINMDM_ORT_NODE is unset: set it to an npm prefix with onnxruntime-node installed "
                    "(npm install --prefix DIR onnxruntime-node)")
    modules = Path(prefix) / "node_modules"
    if not (modules / "onnxruntime-node").is_dir():
        pytest.skip(f"SINMDM_ORT_NODE={prefix} has no node_modules/onnxruntime-node")
    return dict(os.environ, NODE_PATH=str(modules))


def run_check(model: Path, directory: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run(["node", str(CHECK), str(model), str(directory), *extra], capture_output=True, text=True,
                          env=node_environment(), timeout=300)


@pytest.mark.parametrize("name", list(CASES))
def test_the_node_port_reproduces_the_vectors(vectors, name):
    result = run_check(DEMO_MODEL, vectors[name], "--json")
    assert result.returncode == 0, result.stdout + result.stderr
    report = json.loads(result.stdout)
    assert report["problems"] == [] and report["ok"]
    assert report["features"] <= TOLERANCE and report["smoothed"] <= TOLERANCE
    assert report["smooth"] == manifest_of(vectors[name])["options"]["smooth"]
    assert report["positions_of_size"] <= TOLERANCE and report["decode_only_positions_of_size"] <= TOLERANCE
    assert report["steps"] == manifest_of(vectors[name])["options"]["steps"]


def test_without_a_sidecar_the_port_reads_the_vectors_metadata(vectors, tmp_path):
    bare = tmp_path / "bare_w64.onnx"
    shutil.copyfile(DEMO_MODEL, bare)
    result = run_check(bare, vectors["few-steps"], "--json")
    assert result.returncode == 0, result.stdout + result.stderr
    assert json.loads(result.stdout)["metadata"] == str(vectors["few-steps"] / "metadata.json")


def test_the_node_port_fails_on_vectors_it_does_not_reproduce(vectors, tmp_path):
    changed = tmp_path / "changed"
    shutil.copytree(vectors["few-steps"], changed)
    features = np.fromfile(changed / "features.f32", dtype="<f4")
    features[1000] += 1e-3
    features.tofile(changed / "features.f32")
    result = run_check(DEMO_MODEL, changed)
    assert result.returncode == 1 and "FAILED" in result.stdout, result.stdout + result.stderr


def test_the_node_port_refuses_bad_input_with_one_line(vectors, tmp_path):
    other = tmp_path / "other.onnx"
    other.write_bytes(DEMO_MODEL.read_bytes() + b"\0")
    for args, words in [((DEMO_MODEL, tmp_path / "none"), "cannot read vectors manifest"),
                        ((tmp_path / "none.onnx", vectors["few-steps"]), "does not exist"),
                        ((other, vectors["few-steps"]), "sha256 differs")]:
        result = run_check(*args)
        assert result.returncode == 2 and words in result.stderr and result.stderr.count("\n") == 1, result.stderr
