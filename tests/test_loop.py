"""Seamless loops (`sinmdm-run sample --loop`): circular windows, the seam, errors, determinism."""

from __future__ import annotations

import hashlib
import importlib.util
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from sinmdm.runtime import SamplingOptions, generate, load_model, read_bvh
from sinmdm.runtime.animation import animation_from_bvh, global_positions
from sinmdm.runtime.errors import SinMDMError
from sinmdm.runtime.model import MotionModel
from sinmdm.runtime.sampler import Guide, WindowedDenoiser, circular_window_starts, cycle_displacement, sample_features

from .conftest import DEMO_CLIP, ROOT, run_cli


def _bench():
    spec = importlib.util.spec_from_file_location("loop_seam", ROOT / "bench" / "loop_seam.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


loop_seam = _bench()


def digest(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


class StubDenoiser:
    """A 'graph' of a fixed window that applies `fn` to each window and records what it saw."""

    def __init__(self, window: int, fn=lambda x: x):
        self.window, self.fn, self.seen = window, fn, []

    def __call__(self, x_t: np.ndarray, t: np.ndarray) -> np.ndarray:
        assert x_t.shape[-1] == self.window and x_t.dtype == np.float32
        self.seen.append(x_t.copy())
        return self.fn(x_t).astype(np.float32)


def stub_model(window: int, fn=lambda x: x) -> MotionModel:
    return MotionModel(codec=SimpleNamespace(fps=30.0), alphas_cumprod=np.zeros(1), receptive_field=0,
                       trained_window=window, denoisers={window: StubDenoiser(window, fn)}, metadata={})


CIRCLES = [(64, 64, 32), (65, 64, 32), (97, 64, 32), (128, 64, 32), (130, 48, 20), (200, 64, 64), (10, 4, 3), (7, 7, 1), (9, 4, 4)]


@pytest.mark.parametrize("frames, window, hop", CIRCLES)
def test_circular_windows_blend_back_to_the_input(frames, window, hop):
    """A denoiser that returns its input: every frame, the wrap included, comes back unchanged,
    and every window holds consecutive frames of the circle."""
    model = stub_model(window)
    denoise = WindowedDenoiser(model, frames, hop, loop=True)
    starts = denoise.starts
    assert len(starts) == -(-frames // hop) and starts[0] == 0
    gaps = np.diff(np.append(starts, frames))  # the last gap is the one across the wrap
    assert gaps.max() <= hop and gaps.max() - gaps.min() <= 1
    if frames % hop == 0:
        assert np.array_equal(starts, np.arange(0, frames, hop))

    rng = np.random.default_rng(frames)
    x = rng.standard_normal((2, 3, frames)).astype(np.float32).astype(np.float64)
    x[:, 0] = np.arange(frames)  # channel 0: the frame index, to check what each window holds
    out = denoise(x, 10)
    np.testing.assert_allclose(out, x, rtol=1e-12, atol=1e-12)
    (batch,) = model.denoisers[window].seen
    assert batch.shape == (2 * len(starts), 3, window)
    steps = np.diff(batch[:, 0].astype(np.int64), axis=-1) % frames
    assert np.all(steps == 1)  # consecutive modulo the length: windows cross the end into the start
    if len(starts) > 1 and hop < window:
        wraps = [row for row in batch[:, 0] if frames - 1 in row and 0 in row]
        assert wraps, "some window must hold the last and the first frame together"


def test_the_wrap_is_just_another_window_boundary():
    """With a position-dependent (non-identity) denoiser, rotating the input by one hop rotates
    the output by one hop: the seam is treated exactly like every other frame."""
    frames, window, hop = 128, 32, 16
    fn = lambda x: np.tanh(x) * (1.0 + np.arange(x.shape[-1]) / x.shape[-1])  # noqa: E731
    x = np.random.default_rng(0).standard_normal((1, 4, frames)).astype(np.float32).astype(np.float64)
    a = WindowedDenoiser(stub_model(window, fn), frames, hop, loop=True)(x, 5)
    b = WindowedDenoiser(stub_model(window, fn), frames, hop, loop=True)(np.roll(x, hop, axis=-1), 5)
    np.testing.assert_allclose(np.roll(a, hop, axis=-1), b, rtol=1e-12, atol=1e-12)
    flat = WindowedDenoiser(stub_model(window, fn), frames, hop)(x, 5)  # not a loop: the ends differ
    assert not np.allclose(np.roll(flat, hop, axis=-1), WindowedDenoiser(stub_model(window, fn), frames, hop)(
        np.roll(x, hop, axis=-1), 5))


def test_even_coverage_and_too_short_circles():
    denoise = WindowedDenoiser(stub_model(64), 256, 32, loop=True)
    coverage = 1.0 / denoise.normaliser
    assert np.ptp(coverage) < 1e-9  # tents at half-window hops sum to a constant on the circle
    with pytest.raises(SinMDMError, match="at least one window"):
        circular_window_starts(40, 64, 32)
    with pytest.raises(SinMDMError, match="64 frames"):
        WindowedDenoiser(stub_model(64), 63, loop=True)


def test_loop_refuses_guides_and_short_lengths():
    model = load_model()
    guide = Guide(reference=np.zeros((model.features, 64)), keep=np.ones((model.features, 64)))
    with pytest.raises(SinMDMError, match="guide"):
        sample_features(model, 128, SamplingOptions(steps=2), guide=guide, loop=True)
    with pytest.raises(SinMDMError) as info:
        sample_features(model, 40, SamplingOptions(steps=2), loop=True)
    assert "64 frames" in str(info.value) and "\n" not in str(info.value)


def _run_sample(out: Path, *args: str, env: dict | None = None) -> dict:
    result = run_cli("sinmdm-run", "sample", "--out", str(out), "--json", *args, env=env, check=True)
    return json.loads(result.stdout)


def test_too_short_loop_exits_2_with_one_line(tmp_path, no_torch_env):
    for args in (["--frames", "63"], ["--seconds", "1"]):
        result = run_cli("sinmdm-run", "sample", "--loop", "--out", str(tmp_path / "o"), *args, env=no_torch_env)
        assert result.returncode == 2 and "Traceback" not in result.stderr
        assert len(result.stderr.strip().splitlines()) == 1 and "at least one window" in result.stderr
        assert "64 frames" in result.stderr
        assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())
    summary = _run_sample(tmp_path / "one", "--loop", "--frames", "64", "--steps", "4")  # exactly one window is enough
    assert read_bvh(summary["files"][0]).frames == 64


def test_same_seed_same_bytes_with_loop(tmp_path, no_torch_env):
    args = ("--loop", "--seconds", "4", "--steps", "8", "--seed", "5")
    a = _run_sample(tmp_path / "a", *args, "--count", "2", env=no_torch_env)
    b = _run_sample(tmp_path / "b", *args, "--count", "2")
    c = _run_sample(tmp_path / "c", "--loop", "--seconds", "4", "--steps", "8", "--seed", "6", env=no_torch_env)
    plain = _run_sample(tmp_path / "plain", "--seconds", "4", "--steps", "8", "--seed", "5")
    assert [digest(p) for p in a["files"]] == [digest(p) for p in b["files"]]
    assert digest(a["files"][1]) == digest(c["files"][0])  # sample i of a crowd reproduces alone
    assert digest(a["files"][0]) != digest(plain["files"][0])
    assert a["loop"] is True and a["loop_displacement_m"] == b["loop_displacement_m"]
    assert a["loop_displacement_m"][1] == c["loop_displacement_m"][0]
    assert "loop" not in plain and read_bvh(a["files"][0]).frames == 120


def test_api_displacement_is_the_root_motion_per_cycle():
    model = load_model()
    codec = model.codec
    result = generate(model, 96, SamplingOptions(count=2, seed=1, steps=6), loop=True)
    assert result.loop_displacement.shape == (2, 2)
    np.testing.assert_allclose(result.loop_displacement, cycle_displacement(codec, result.features))
    h1, h2 = codec.horizontal_axes
    dx, _, dz = codec.layout.indices(("root",))
    for features, clip, shift in zip(result.features, result.clips, result.loop_displacement):
        assert clip.frames == 96  # frame T (frame 0 of the next cycle) is not written
        root = animation_from_bvh(clip).translations[:, codec.trajectory_joint] * codec.scale
        # last frame -> first frame of the next cycle is frame 0's velocity (the step across the wrap)
        across = np.array([root[0, h1] + shift[0] - root[-1, h1], root[0, h2] + shift[1] - root[-1, h2]])
        np.testing.assert_allclose(across, features[0, [dx, dz]], atol=1e-4)
    assert generate(model, 96, SamplingOptions(steps=2)).loop_displacement is None


def _seams(summary: dict, codec, axes: list[str] | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    steps, seconds, within = [], [], []
    for i, path in enumerate(p for p in summary["files"] if p.endswith(".bvh")):
        clip = read_bvh(path)
        if axes is None:  # not a loop: the displacement a loop would have, from the sample's features
            shift = loop_seam.cycle_displacement(codec, np.load(Path(path).with_suffix(".npz"))["features"])
        else:
            shift = np.array([summary["loop_displacement_m"][i][a] for a in axes])
        s = loop_seam.seam(codec, clip, shift)
        p = global_positions(animation_from_bvh(clip))
        own = np.linalg.norm(np.diff(p, axis=0), axis=-1).mean(axis=-1)
        steps.append(s["step"])
        seconds.append(s["second"])
        within.append(s["step"] <= np.percentile(own, 95))
    return np.array(steps), np.array(seconds), np.array(within)


def test_loop_seam_is_below_the_clips_median_change(tmp_path):
    """8 loops of 4 s from the demo model: the jump at the wrap (after the cycle's root
    displacement) is below the training clip's median frame-to-frame change, in position and
    in velocity (second difference); without --loop the end-start jump is several times larger."""
    model = load_model()
    codec = model.codec
    reference = loop_seam.clip_medians(codec, DEMO_CLIP)
    args = ("--seconds", "4", "--count", "8", "--seed", "0")
    looped = _run_sample(tmp_path / "loop", "--loop", *args)
    plain = _run_sample(tmp_path / "plain", *args, "--npz")
    axes = list(looped["loop_displacement_m"][0])
    assert len(axes) == 2
    step, second, within = _seams(looped, codec, axes)
    assert np.median(step) < reference["step"] and np.median(second) < reference["second"]
    assert within.mean() >= 7 / 8  # the wrap is like any other frame of the loop, not its worst jump
    plain_step, plain_second, _ = _seams(plain, codec, None)
    assert np.median(plain_step) > 2 * reference["step"] and np.median(plain_step) > 4 * np.median(step)
    assert np.median(plain_second) > 5 * reference["second"] and np.median(plain_second) > 5 * np.median(second)
