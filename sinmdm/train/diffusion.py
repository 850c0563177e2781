"""Forward diffusion process and the x0-prediction training loss (torch).

The cumulative alphas come from sinmdm.runtime.schedule, the single source of
truth shared with export and sampling; they are kept in float64 and cast per use.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor, nn

from sinmdm.runtime.errors import SinMDMError
from sinmdm.runtime.schedule import cosine_alphas_cumprod

# Maps timesteps (B,) to per-example loss weights (B,).
LossWeighting = Callable[[Tensor], Tensor]

LOSS_WEIGHTINGS = ("uniform", "min-snr")


def min_snr_weighting(alphas_cumprod: np.ndarray, gamma: float = 5.0) -> LossWeighting:
    """Min-SNR-gamma (Hang et al. 2023) for an x0 target: weight min(SNR_t, gamma), scaled to a mean
    of 1 over t so that the learning rate means what it meant under the paper's uniform loss. Against
    the uniform loss it trains the cleaner half (detail) more and the noisiest steps (layout) less."""
    abar = np.asarray(alphas_cumprod, dtype=np.float64)
    weights = np.minimum(abar / np.maximum(1.0 - abar, 1e-12), gamma)
    table = torch.as_tensor(weights / weights.mean(), dtype=torch.float32)
    return lambda t: table.to(t.device)[t.long()]


def loss_weighting(name: str, alphas_cumprod: np.ndarray) -> LossWeighting | None:
    """The weighting over t a recipe names: None for the paper's uniform loss."""
    if name not in LOSS_WEIGHTINGS:
        raise SinMDMError(f"unknown loss weighting {name!r}: use {' or '.join(LOSS_WEIGHTINGS)}")
    return min_snr_weighting(alphas_cumprod) if name == "min-snr" else None


def _per_example(values: Tensor, t: Tensor, like: Tensor) -> Tensor:
    """values[t] cast to like's dtype/device and shaped (B, 1, ..., 1) to broadcast against it."""
    picked = values.to(like.device)[t.to(like.device).long()].to(like.dtype)
    return picked.reshape((-1,) + (1,) * (like.dim() - 1))


class GaussianDiffusion:
    """q(x_t | x0) and the paper's loss: plain MSE between model(x_t, t) and x0."""

    def __init__(self, alphas_cumprod: np.ndarray | None = None,
                 loss_weighting: LossWeighting | None = None) -> None:
        abar = cosine_alphas_cumprod() if alphas_cumprod is None else np.asarray(alphas_cumprod)
        self.alphas_cumprod = torch.as_tensor(abar, dtype=torch.float64)
        self.sqrt_alphas_cumprod = self.alphas_cumprod.sqrt()
        self.sqrt_one_minus_alphas_cumprod = (1.0 - self.alphas_cumprod).sqrt()
        self.loss_weighting = loss_weighting

    @property
    def num_timesteps(self) -> int:
        return len(self.alphas_cumprod)

    def sample_timesteps(self, batch: int, generator: torch.Generator | None = None,
                         device: torch.device | str | None = None) -> Tensor:
        """Timesteps uniform in [0, num_timesteps - 1], independent per batch element."""
        return torch.randint(0, self.num_timesteps, (batch,), generator=generator, device=device)

    def q_sample(self, x0: Tensor, t: Tensor, noise: Tensor) -> Tensor:
        """x_t = sqrt(abar_t) x0 + sqrt(1 - abar_t) noise."""
        return (_per_example(self.sqrt_alphas_cumprod, t, x0) * x0
                + _per_example(self.sqrt_one_minus_alphas_cumprod, t, x0) * noise)

    def training_loss(self, model: nn.Module, x0: Tensor, t: Tensor | None = None,
                      noise: Tensor | None = None, generator: torch.Generator | None = None,
                      extra: Callable[[Tensor, Tensor, Tensor], Tensor] | None = None) -> Tensor:
        """Mean squared error of the x0 prediction over all elements (scalar), plus
        `extra(prediction, x0, t)` when given (a geometric term, e.g. train.foot_loss)."""
        if t is None:
            t = self.sample_timesteps(x0.shape[0], generator=generator, device=x0.device)
        if noise is None:
            noise = torch.randn(x0.shape, generator=generator, dtype=x0.dtype, device=x0.device)
        prediction = model(self.q_sample(x0, t, noise), t).to(x0.dtype)
        if self.loss_weighting is None:
            loss = F.mse_loss(prediction, x0)
        else:
            per_example = ((prediction - x0) ** 2).flatten(1).mean(dim=1)
            loss = (self.loss_weighting(t).to(per_example) * per_example).mean()
        return loss if extra is None else loss + extra(prediction, x0, t)
