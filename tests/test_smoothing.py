"""The temporal smoothing of sampled features (runtime.smoothing): the filter itself, where
generate applies it (loops stay seamless, a guide's kept features stay exact), the model's
measured setting and the option's checks."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from sinmdm.runtime import SamplingOptions, generate, load_model
from sinmdm.runtime.errors import OptionError
from sinmdm.runtime.options import DEFAULT_SMOOTH
from sinmdm.runtime.sampler import cycle_displacement, sample_features
from sinmdm.runtime.smoothing import gaussian_weights, smooth_frames

from .conftest import call_cli

RNG = np.random.default_rng(3)
NOISY = RNG.normal(size=(2, 90, 7)).astype(np.float32)


def test_weights_are_a_normalised_symmetric_gaussian():
    weights = gaussian_weights(1.0)
    assert len(weights) == 9 and abs(weights.sum() - 1) < 1e-12
    np.testing.assert_allclose(weights, weights[::-1])
    assert weights.argmax() == 4


def test_off_returns_the_features_untouched():
    assert smooth_frames(NOISY, 0.0) is NOISY


def test_a_constant_or_a_straight_line_passes_unchanged():
    frames = np.arange(90, dtype=np.float32)
    line = np.broadcast_to(frames[None, :, None] * 0.1 + 2, (1, 90, 3)).copy()
    np.testing.assert_allclose(smooth_frames(line, 1.0)[:, 5:-5], line[:, 5:-5], atol=1e-5)
    constant = np.full((1, 40, 2), 3.5, np.float32)
    np.testing.assert_allclose(smooth_frames(constant, 2.0, wrap=True), constant, atol=1e-6)


def test_in_place_gives_the_same_values():
    copy = NOISY.copy()
    np.testing.assert_array_equal(smooth_frames(copy, 1.0, keep=np.zeros((90, 7)), out=copy), smooth_frames(NOISY, 1.0))


def test_frame_to_frame_noise_drops():
    smoothed = smooth_frames(NOISY, 1.0)
    assert np.abs(np.diff(smoothed, n=3, axis=1)).mean() < 0.25 * np.abs(np.diff(NOISY, n=3, axis=1)).mean()
    assert smoothed.dtype == NOISY.dtype and smoothed.shape == NOISY.shape


def test_a_loop_is_smoothed_as_a_circle():
    """Wrapped, the filter commutes with turning the cycle: the seam is a frame like any other,
    and each channel's sum (a root velocity's displacement per cycle) is kept."""
    smoothed = smooth_frames(NOISY, 1.5, wrap=True)
    np.testing.assert_allclose(smooth_frames(np.roll(NOISY, 17, axis=1), 1.5, wrap=True),
                               np.roll(smoothed, 17, axis=1), atol=1e-5)
    np.testing.assert_allclose(smoothed.sum(axis=1), NOISY.sum(axis=1), atol=1e-4)


def test_kept_features_stay_exact():
    keep = np.zeros((90, 7))
    keep[:30] = 1
    keep[:, 2] = 1
    smoothed = smooth_frames(NOISY, 1.0, keep=keep)
    np.testing.assert_array_equal(smoothed[:, :30], NOISY[:, :30])
    np.testing.assert_array_equal(smoothed[:, :, 2], NOISY[:, :, 2])
    assert not np.allclose(smoothed[:, 40:, 0], NOISY[:, 40:, 0])


def test_generate_smooths_what_the_sampler_gives():
    model = load_model()
    options = SamplingOptions(count=2, seed=4, steps=4, cleanup=False)
    raw = sample_features(model, 120, replace(options, smooth=0.0))
    off = generate(model, 120, replace(options, smooth=0.0))
    on = generate(model, 120, replace(options, smooth=1.0))
    np.testing.assert_array_equal(off.features, raw)
    np.testing.assert_allclose(on.features, smooth_frames(raw, 1.0), atol=1e-6)
    assert on.options.smooth == 1.0 and generate(model, 120, options).options.smooth == model.default_smooth


def test_a_smoothed_loop_keeps_its_displacement_per_cycle():
    model = load_model()
    options = SamplingOptions(count=2, seed=1, steps=4, smooth=2.0)
    looped = generate(model, 96, options, loop=True)
    raw = sample_features(model, 96, options.resolve(model, 96, loop=True), loop=True)
    np.testing.assert_allclose(looped.loop_displacement, cycle_displacement(model.codec, raw), atol=1e-4)


def test_the_models_measured_setting_is_the_default():
    model = load_model()
    assert model.default_smooth == 0.0  # the demo's samples shake less than its clip (0.6x): calibrated to none
    assert SamplingOptions().resolve(model, 120).smooth == 0.0
    assert SamplingOptions(smooth=2.0).resolve(model, 120).smooth == 2.0
    del model.metadata["sampling_defaults"]["smooth"]  # a model calibrated before the smoothing existed
    assert model.default_smooth == DEFAULT_SMOOTH == 1.0


@pytest.mark.parametrize("value", [-1.0, 10.5, float("nan"), True, "1"])
def test_bad_smoothing_is_refused(value):
    with pytest.raises(OptionError, match="smooth"):
        SamplingOptions(smooth=value)


def test_cli_smooth_option(tmp_path):
    result = call_cli("sinmdm-run", "sample", "--seconds", "3", "--steps", "3", "--smooth", "1.5", "--out",
                      str(tmp_path / "a"), "--json", check=True)
    assert json.loads(result.stdout)["smooth"] == 1.5
    result = call_cli("sinmdm-run", "sample", "--seconds", "3", "--steps", "3", "--out", str(tmp_path / "b"), "--json",
                      check=True)
    assert json.loads(result.stdout)["smooth"] == load_model().default_smooth
    bad = call_cli("sinmdm-run", "sample", "--smooth", "-2", "--out", str(tmp_path / "c"))
    assert bad.returncode == 2 and "smooth" in bad.stderr and len(bad.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "c").exists()


def test_joint_control_keeps_its_joints_exact_with_smoothing():
    from sinmdm.runtime.applications import load_reference, plan_control, run_plan

    from .conftest import DEMO_CLIP

    model = load_model()
    reference = load_reference(model, DEMO_CLIP)
    plan = plan_control(model, reference, joints="upper-body")
    result = run_plan(model, plan, SamplingOptions(count=2, seed=0, steps=4, smooth=2.0))
    kept = np.flatnonzero(plan.guide.keep[:, 0])
    free = np.setdiff1d(np.arange(model.features), kept)
    for features in result.features:
        np.testing.assert_allclose(features[:, kept], reference.features[:, kept], atol=1e-5)
    raw = run_plan(model, plan, SamplingOptions(count=2, seed=0, steps=4, smooth=0.0))
    assert np.abs(np.diff(result.features[:, :, free], n=3, axis=1)).mean() < np.abs(
        np.diff(raw.features[:, :, free], n=3, axis=1)).mean()
