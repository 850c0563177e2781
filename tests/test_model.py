"""Tests of the denoiser (sinmdm.train.model) and the torch diffusion (sinmdm.train.diffusion)."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

torch = pytest.importorskip("torch")
from torch import nn  # noqa: E402

from sinmdm.runtime.schedule import cosine_alphas_cumprod  # noqa: E402
from sinmdm.train.diffusion import GaussianDiffusion  # noqa: E402
from sinmdm.train.model import (  # noqa: E402
    Denoiser,
    GroupNorm,
    ModelConfig,
    QnA,
    count_parameters,
    receptive_field,
    timestep_embedding,
)

PAPER_PARAMETERS_F174 = 5_262_546
PER_FEATURE_SLOPE = 1_537  # in conv 768 F + out conv 769 F


def tiny_config(**overrides) -> ModelConfig:
    settings = dict(features=6, width=32, groups=8, heads=4)
    settings.update(overrides)
    return ModelConfig(**settings)


def randomise_(model: nn.Module, seed: int = 0, scale: float = 0.3) -> nn.Module:
    """Replace every parameter (including the zero-initialised ones) by random values."""
    generator = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for p in model.parameters():
            p.copy_(torch.randn(p.shape, generator=generator, dtype=p.dtype) * scale)
    return model


# ---------------------------------------------------------------- parameters


def test_paper_configuration_has_exactly_the_papers_parameter_count():
    assert count_parameters(Denoiser(ModelConfig(features=174))) == PAPER_PARAMETERS_F174


@pytest.mark.parametrize("features", [3, 315])
def test_parameter_count_grows_linearly_with_features(features):
    expected = PAPER_PARAMETERS_F174 + PER_FEATURE_SLOPE * (features - 174)
    assert count_parameters(Denoiser(ModelConfig(features=features))) == expected


def test_config_round_trips_through_a_dict():
    config = ModelConfig(features=12, width=64, groups=16, norm="frame", dropout=0.1)
    assert ModelConfig.from_dict(config.to_dict()) == config
    with pytest.raises(ValueError):
        ModelConfig.from_dict({**config.to_dict(), "bogus": 1})
    with pytest.raises(ValueError):
        ModelConfig(features=12, attention_window=4)


# ---------------------------------------------------------------- QnA


def naive_qna(qna: QnA, x: torch.Tensor) -> torch.Tensor:
    """Builds the key tensor and runs an explicit softmax per window, windows clipped at the ends."""
    batch, _, frames = x.shape
    heads, d, p = qna.heads, qna.head_dim, qna.span // 2
    q = qna.query / (qna.query.norm(dim=-1, keepdim=True) + 1e-6) / math.sqrt(d)  # (heads, d)
    keys = (x.transpose(1, 2) @ qna.key_weight + qna.key_bias).transpose(1, 2)  # (B, C, T)
    scores = (keys.reshape(batch, heads, d, frames) * q[None, :, :, None]).sum(2)  # (B, heads, T)
    values = qna.to_value(x).reshape(batch, heads, d, frames)
    out = torch.zeros_like(values)
    for t in range(frames):
        window = list(range(max(0, t - p), min(frames, t + p + 1)))
        logits = scores[:, :, window] + qna.rel_pos_bias[:, [j - t + p for j in window]]
        attention = torch.softmax(logits, dim=-1)  # (B, heads, |window|)
        out[..., t] = (values[..., window] * attention[:, :, None, :]).sum(-1)
    return qna.to_out(out.reshape(batch, heads * d, frames))


def random_qna(window: int, seed: int, dtype: torch.dtype = torch.float32) -> QnA:
    qna = QnA(channels=16, heads=4, span=window).to(dtype)
    return randomise_(qna, seed=seed, scale=0.5)


@pytest.mark.parametrize("window", [3, 5])
@pytest.mark.parametrize("frames", [1, 2, 5, 17])
def test_qna_matches_a_naive_windowed_softmax(window, frames):
    qna = random_qna(window, seed=frames * 10 + window)
    x = torch.randn(2, 16, frames, generator=torch.Generator().manual_seed(frames))
    with torch.no_grad():
        torch.testing.assert_close(qna(x), naive_qna(qna, x), atol=1e-5, rtol=0)


@pytest.mark.parametrize("window", [3, 5])
def test_qna_does_not_overflow_with_logits_of_magnitude_1e3(window):
    # float64 overflows exp() past ~709, so only the max subtraction keeps this finite;
    # float64 also keeps the logits' own rounding (ulp at 1e3) below the tolerance.
    qna = random_qna(window, seed=7, dtype=torch.float64)
    with torch.no_grad():
        q_unit = qna.query / qna.query.norm(dim=-1, keepdim=True)
        qna.key_bias.copy_((1e3 * math.sqrt(qna.head_dim) * q_unit).reshape(-1))  # +1e3 per head
        qna.key_weight.mul_(20.0)  # spread of the logits over time: tens
        x = torch.randn(2, 16, 17, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
        scores = qna.logits(x)
        assert scores.abs().min() > 500 and scores.std(dim=2).min() > 5
        out = qna(x)
        assert torch.isfinite(out).all()
        torch.testing.assert_close(out, naive_qna(qna, x), atol=1e-5, rtol=0)
        # float32 at the same magnitude stays finite (its logits carry ~1e-4 rounding).
        out32 = qna.float()(x.float())
        assert torch.isfinite(out32).all()


# ---------------------------------------------------------------- GroupNorm


@pytest.mark.parametrize("frames", [1, 17])
def test_group_norm_equals_torch_group_norm(frames):
    ours, reference = GroupNorm(8, 32), nn.GroupNorm(8, 32, eps=1e-5)
    randomise_(ours, seed=3, scale=1.0)
    reference.load_state_dict(ours.state_dict())
    x = torch.randn(3, 32, frames) * 4 + 2
    torch.testing.assert_close(ours(x), reference(x), atol=1e-5, rtol=1e-5)


def test_group_norm_folds_the_time_modulation():
    ours, reference = GroupNorm(8, 32), nn.GroupNorm(8, 32, eps=1e-5)
    randomise_(ours, seed=5, scale=1.0)
    reference.load_state_dict(ours.state_dict())
    x, scale, shift = torch.randn(3, 32, 9) * 3, torch.randn(3, 32), torch.randn(3, 32)
    expected = reference(x) * (1 + scale[:, :, None]) + shift[:, :, None]
    torch.testing.assert_close(ours(x, scale, shift), expected, atol=1e-5, rtol=1e-5)


def test_per_frame_group_norm_normalises_each_frame_on_its_own():
    ours, reference = GroupNorm(8, 32, per_frame=True), nn.GroupNorm(8, 32, eps=1e-5)
    randomise_(ours, seed=4, scale=1.0)
    reference.load_state_dict(ours.state_dict())
    x = torch.randn(3, 32, 11) * 4 + 2
    per_frame = reference(x.transpose(1, 2).reshape(-1, 32, 1)).reshape(3, 11, 32).transpose(1, 2)
    torch.testing.assert_close(ours(x), per_frame, atol=1e-5, rtol=1e-5)


# ---------------------------------------------------------------- denoiser


def test_time_embedding_puts_the_cosine_half_first():
    emb = timestep_embedding(torch.tensor([0, 1]), 256)
    assert emb.shape == (2, 256)
    assert torch.equal(emb[0, :128], torch.ones(128)) and torch.equal(emb[0, 128:], torch.zeros(128))
    freq1 = math.exp(-math.log(10000) / 128)
    torch.testing.assert_close(emb[1, [0, 1, 128, 129]],
                               torch.tensor([math.cos(1.0), math.cos(freq1), math.sin(1.0), math.sin(freq1)]))


def test_fresh_model_outputs_exact_zeros():
    model = Denoiser(tiny_config())
    x = torch.randn(2, 6, 9)
    assert torch.equal(model(x, torch.tensor([3, 900])), torch.zeros_like(x))


@pytest.fixture(scope="module")
def paper_model() -> Denoiser:
    torch.manual_seed(0)
    return randomise_(Denoiser(ModelConfig(features=174)), scale=0.02).eval()


@pytest.mark.parametrize("frames", [1, 23, 64, 200])
def test_forward_shape_and_eval_determinism(paper_model, frames):
    x = torch.randn(2, 174, frames)
    t = torch.tensor([0, 999])
    with torch.no_grad():
        first, second = paper_model(x, t), paper_model(x, t)
    assert first.shape == x.shape and torch.isfinite(first).all()
    assert torch.equal(first, second)
    assert first.abs().max() > 0


def test_float_and_integer_timesteps_agree():
    model = randomise_(Denoiser(tiny_config()), scale=0.2).eval()
    x = torch.randn(2, 6, 8)
    with torch.no_grad():
        assert torch.equal(model(x, torch.tensor([5, 700])), model(x, torch.tensor([5.0, 700.0])))


def test_dropout_is_active_in_train_mode_only():
    model = randomise_(Denoiser(tiny_config()), scale=0.2)
    x, t = torch.randn(2, 6, 8), torch.tensor([5, 700])
    model.train()
    assert not torch.equal(model(x, t), model(x, t))


def test_receptive_field_is_exact_with_per_frame_norm():
    config = tiny_config(norm="frame")
    radius = receptive_field(config) // 2
    assert receptive_field(ModelConfig(features=174)) == 23 and radius == 11
    model = randomise_(Denoiser(config), seed=5).double().eval()
    x = torch.randn(1, 6, 201, dtype=torch.float64)
    t = torch.tensor([500])
    inside = torch.zeros(201, dtype=torch.bool)
    inside[100 - radius: 100 + radius + 1] = True

    # Perturbing frame 100 moves only the outputs within the radius (float64: the QnA's
    # global max subtraction could move distant frames only by rounding, ~1e-16).
    bumped = x.clone()
    bumped[:, :, 100] += 1.0
    with torch.no_grad():
        change = (model(bumped, t) - model(x, t)).abs().amax(dim=(0, 1))
    assert change[~inside].max() < 1e-12
    assert change[100] > 1e-3

    # The bound is tight: output frame 100 depends on input frames 100 +- radius, and the
    # dependence at the edges, though small after 11 hops, is structurally non-zero.
    x.requires_grad_(True)
    model(x, t)[:, :, 100].sum().backward()
    sensitivity = x.grad.abs().amax(dim=(0, 1))
    assert torch.equal(inside, sensitivity > 0)


@pytest.mark.filterwarnings("ignore:`torch.jit.trace")
def test_trace_generalises_across_lengths_without_warnings():
    model = randomise_(Denoiser(tiny_config()), scale=0.2).eval()
    with warnings.catch_warnings():
        warnings.simplefilter("error", torch.jit.TracerWarning)
        traced = torch.jit.trace(model, (torch.randn(2, 6, 16), torch.tensor([1, 2])))
    assert "einsum" not in str(traced.graph)
    with torch.no_grad():
        for batch, frames in [(1, 1), (3, 37)]:
            x, t = torch.randn(batch, 6, frames), torch.randint(0, 1000, (batch,))
            torch.testing.assert_close(traced(x, t), model(x, t), atol=1e-6, rtol=1e-5)


# ---------------------------------------------------------------- diffusion


def test_q_sample_uses_the_runtime_schedule():
    diffusion = GaussianDiffusion()
    abar = cosine_alphas_cumprod(1000)
    x0, noise = torch.randn(3, 4, 5), torch.randn(3, 4, 5)
    t = torch.tensor([0, 321, 999])
    coef = torch.as_tensor(abar[t.numpy()], dtype=torch.float32)[:, None, None]
    expected = coef.sqrt() * x0 + (1 - coef).sqrt() * noise
    torch.testing.assert_close(diffusion.q_sample(x0, t, noise), expected)
    assert diffusion.alphas_cumprod.dtype == torch.float64
    assert np.array_equal(diffusion.alphas_cumprod.numpy(), abar)


def test_sample_timesteps_cover_the_range_uniformly():
    t = GaussianDiffusion().sample_timesteps(20000, torch.Generator().manual_seed(0), "cpu")
    assert t.dtype == torch.int64 and t.min() >= 0 and t.max() <= 999
    assert abs(t.float().mean().item() - 499.5) < 10


def test_training_loss_is_plain_mse_of_the_x0_prediction():
    diffusion = GaussianDiffusion()
    model = randomise_(Denoiser(tiny_config()), scale=0.2).eval()
    x0, noise, t = torch.randn(2, 6, 8), torch.randn(2, 6, 8), torch.tensor([10, 600])
    with torch.no_grad():
        loss = diffusion.training_loss(model, x0, t=t, noise=noise)
        expected = ((model(diffusion.q_sample(x0, t, noise), t) - x0) ** 2).mean()
    torch.testing.assert_close(loss, expected)


def test_training_loss_backpropagates_under_bf16_autocast():
    model = randomise_(Denoiser(tiny_config()), scale=0.2)
    x0 = torch.randn(4, 6, 16)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        loss = GaussianDiffusion().training_loss(model, x0, generator=torch.Generator().manual_seed(0))
    loss.backward()
    assert loss.dtype == torch.float32 and torch.isfinite(loss)
    assert all(torch.isfinite(p.grad).all() for p in model.parameters())


def test_training_a_tiny_model_lowers_the_loss():
    torch.manual_seed(0)
    generator = torch.Generator().manual_seed(0)
    diffusion = GaussianDiffusion()
    model = Denoiser(tiny_config(features=8))
    x0 = torch.randn(1, 8, 32, generator=generator).repeat(8, 1, 1)
    probe_t = torch.arange(0, 1000, 125)
    probe_noise = torch.randn(x0.shape, generator=generator)

    def probe_loss() -> float:
        model.eval()
        with torch.no_grad():
            value = diffusion.training_loss(model, x0, t=probe_t, noise=probe_noise).item()
        model.train()
        return value

    before = probe_loss()
    optimiser = torch.optim.AdamW(model.parameters(), lr=2e-3, weight_decay=0.0)
    for _ in range(60):
        optimiser.zero_grad()
        diffusion.training_loss(model, x0, generator=generator).backward()
        optimiser.step()
    after = probe_loss()
    assert after < 0.6 * before, (before, after)
