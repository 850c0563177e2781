"""The sampling loop's algebra with stub denoisers (no trained model): every sampler, the
composition and ILVR hooks, the timesteps the denoiser sees, and golden numbers."""

from __future__ import annotations

import numpy as np
import pytest

from sinmdm.runtime.sampler import draw, ilvr, sample_loop
from sinmdm.runtime.schedule import Schedule, cosine_alphas_cumprod

SHAPE = (2, 3, 5)  # (samples, features, frames)
SAMPLERS = [("ddpm", 1000, 0.0), ("ddpm", 10, 0.0), ("ddim", 10, 0.0), ("ddim", 10, 0.5), ("ddim", 1, 0.0)]


def start(seed: int = 0) -> tuple[np.ndarray, list[np.random.Generator]]:
    streams = [np.random.default_rng(seed + i) for i in range(SHAPE[0])]
    return draw(streams, SHAPE[1:]), streams


@pytest.mark.parametrize("sampler,steps,eta", SAMPLERS)
def test_a_denoiser_that_knows_the_answer_lands_on_it(sampler, steps, eta):
    target = np.linspace(-1.0, 1.0, np.prod(SHAPE)).reshape(SHAPE)
    schedule = Schedule.from_alphas_cumprod(cosine_alphas_cumprod(), steps)
    x, streams = start()
    out = sample_loop(lambda x_t, t: target, schedule, x, streams, sampler, eta)
    np.testing.assert_allclose(out, target, atol=1e-12)


@pytest.mark.parametrize("sampler,steps,eta", SAMPLERS)
def test_the_denoiser_sees_the_chains_timesteps_high_to_low(sampler, steps, eta):
    schedule = Schedule.from_alphas_cumprod(cosine_alphas_cumprod(), steps)
    seen, progress = [], []
    x, streams = start()
    sample_loop(lambda x_t, t: seen.append(t) or 0.9 * x_t, schedule, x, streams, sampler, eta,
                progress=lambda done, total: progress.append((done, total)))
    assert seen == sorted(schedule.timesteps.tolist(), reverse=True) and seen[0] == 999
    assert seen[-1] == (0 if steps > 1 else 999)  # one step: straight from pure noise
    assert progress == [(i + 1, len(seen)) for i in range(len(seen))]


def test_ddim_with_eta_0_draws_noise_that_changes_nothing():
    schedule = Schedule.from_alphas_cumprod(cosine_alphas_cumprod(), 8)
    x, _ = start(0)
    outs = [sample_loop(lambda x_t, t: np.tanh(x_t), schedule, x, start(seed)[1], "ddim", 0.0) for seed in (0, 100)]
    np.testing.assert_array_equal(outs[0], outs[1])


def test_two_step_ddpm_by_hand():
    """The respaced 2-step chain (timesteps 0 and 999), written out from the formulas."""
    abar_all = cosine_alphas_cumprod()
    schedule = Schedule.from_alphas_cumprod(abar_all, 2)
    assert schedule.timesteps.tolist() == [0, 999]
    x, streams = start(7)
    out = sample_loop(lambda x_t, t: 0.5 * x_t, schedule, x.copy(), streams, "ddpm")

    rngs = [np.random.default_rng(7 + i) for i in range(SHAPE[0])]
    x_hand = np.stack([r.standard_normal(SHAPE[1:]) for r in rngs])
    a0, a1 = abar_all[0], abar_all[999]
    beta1 = 1 - a1 / a0  # the respaced step from 999 to 0
    mean = beta1 * np.sqrt(a0) / (1 - a1) * (0.5 * x_hand) + (1 - a0) * np.sqrt(1 - beta1) / (1 - a1) * x_hand
    beta0 = 1 - a0
    variance_1 = beta1 * (1 - a0) / (1 - a1)  # step 0's log-variance is step 1's (clipped)
    x_hand = mean + np.sqrt(variance_1) * np.stack([r.standard_normal(SHAPE[1:]) for r in rngs])
    x_hand = beta0 / (1 - a0) * (0.5 * x_hand)  # last step: c1 = 1 - (posterior of x0 at t=0), c2 = 0
    np.testing.assert_allclose(out, x_hand, rtol=1e-12, atol=1e-12)


def test_golden_numbers():
    """A fixed seed, a fixed stub and a 4-step chain give these exact numbers (any change to the
    loop's order of draws or coefficients shows here)."""
    schedule = Schedule.from_alphas_cumprod(cosine_alphas_cumprod(), 4)
    x, streams = start(3)
    ddpm = sample_loop(lambda x_t, t: np.sin(x_t) * (1 - t / 1000), schedule, x, streams, "ddpm")
    x, streams = start(3)
    ddim = sample_loop(lambda x_t, t: np.sin(x_t) * (1 - t / 1000), schedule, x, streams, "ddim", 0.3)
    np.testing.assert_allclose(ddpm[0, 0], GOLDEN_DDPM, rtol=1e-10)
    np.testing.assert_allclose(ddim[1, 2], GOLDEN_DDIM, rtol=1e-10)


def test_composition_keeps_what_it_keeps():
    reference = np.full(SHAPE[1:], 0.25)
    keep = np.zeros(SHAPE[1:])
    keep[:, :2] = 1.0
    schedule = Schedule.from_alphas_cumprod(cosine_alphas_cumprod(), 10)
    x, streams = start()
    out = sample_loop(lambda x_t, t: -np.ones_like(x_t), schedule, x, streams, "ddpm",
                      compose=lambda x0: x0 * (1 - keep) + reference * keep)
    np.testing.assert_allclose(out[:, :, :2], 0.25, atol=1e-12)
    np.testing.assert_allclose(out[:, :, 2:], -1.0, atol=1e-12)


def test_ilvr_replaces_the_low_frequencies_by_the_noised_reference():
    """factor 1 (no low-pass): inside the region x becomes q_sample(reference) at each step,
    drawn from the samples' own streams after the step's noise."""
    schedule = Schedule.from_alphas_cumprod(cosine_alphas_cumprod(), 5)
    reference = np.full(SHAPE[1:], 0.7)
    x, streams = start(11)
    seen = []
    hook = ilvr(schedule, reference, np.ones(SHAPE[1:]), factor=1, stop_t=-1, streams=streams)
    sample_loop(lambda x_t, t: seen.append(x_t.copy()) or np.zeros_like(x_t), schedule, x, streams, "ddpm",
                harmonize=hook)
    rngs = [np.random.default_rng(11 + i) for i in range(SHAPE[0])]
    draw(rngs, SHAPE[1:])  # x_T
    for step, x_seen in zip(range(3, -1, -1), seen[1:]):
        draw(rngs, SHAPE[1:])  # the step's own noise
        np.testing.assert_allclose(x_seen, schedule.q_sample(reference, step, draw(rngs, SHAPE[1:])), atol=1e-12)


def test_ilvr_stops_below_its_timestep():
    schedule = Schedule.from_alphas_cumprod(cosine_alphas_cumprod(), 5)
    x = np.ones(SHAPE)
    hook = ilvr(schedule, np.zeros(SHAPE[1:]), np.ones(SHAPE[1:]), factor=1, stop_t=500, streams=start()[1])
    assert hook(x, 0) is x and not np.array_equal(hook(x, 4), x)


GOLDEN_DDPM = [-0.3554306723553835, 0.03995182449311724, 0.21850149984048606, 0.3840176411477686, -0.015904179050838213]
GOLDEN_DDIM = [-0.06873926472993463, 0.548034802778652, -0.050448371565390907, 0.2448022101113938, -0.6075307521626091]
