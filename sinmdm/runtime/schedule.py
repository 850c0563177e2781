"""The cosine noise schedule and the DDPM posterior (float64); the single source
of truth for training, export metadata and sampling."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

NUM_TIMESTEPS = 1000


def cosine_alphas_cumprod(num_timesteps: int = NUM_TIMESTEPS, s: float = 0.008) -> np.ndarray:
    """Cumulative alphas of Nichol & Dhariwal's cosine schedule, with betas capped at 0.999."""
    def abar(u: np.ndarray) -> np.ndarray:
        return np.cos((u + s) / (1 + s) * math.pi / 2) ** 2

    steps = np.arange(num_timesteps, dtype=np.float64)
    betas = np.minimum(1 - abar((steps + 1) / num_timesteps) / abar(steps / num_timesteps), 0.999)
    return np.cumprod(1.0 - betas)


@dataclass(frozen=True)
class Schedule:
    """Diffusion coefficients for a (possibly respaced) chain of timesteps.

    `timesteps[i]` is the original timestep (0..999) that chain step i stands for;
    the network is always fed original timesteps.
    """

    alphas_cumprod: np.ndarray
    timesteps: np.ndarray

    @classmethod
    def from_alphas_cumprod(cls, alphas_cumprod: np.ndarray, steps: int | None = None) -> "Schedule":
        """The full chain, or one respaced to `steps` evenly spaced timesteps (as in improved-diffusion)."""
        abar = np.asarray(alphas_cumprod, dtype=np.float64)
        total = len(abar)
        if steps is None or steps >= total:
            return cls(abar, np.arange(total))
        if steps < 1:
            raise ValueError("steps must be >= 1")
        frac = (total - 1) / max(steps - 1, 1)
        use = np.unique(np.round(np.arange(steps) * frac).astype(np.int64)) if steps > 1 else np.array([total - 1])
        return cls(abar[use], use)

    @property
    def betas(self) -> np.ndarray:
        prev = np.concatenate([[1.0], self.alphas_cumprod[:-1]])
        return 1.0 - self.alphas_cumprod / prev

    @property
    def alphas_cumprod_prev(self) -> np.ndarray:
        return np.concatenate([[1.0], self.alphas_cumprod[:-1]])

    def posterior(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(c1, c2, log_variance): mu = c1 * x0 + c2 * x_t; fixed-small variance, its
        log at the first step replaced by the value at the second."""
        abar, abar_prev, betas = self.alphas_cumprod, self.alphas_cumprod_prev, self.betas
        c1 = betas * np.sqrt(abar_prev) / (1.0 - abar)
        c2 = (1.0 - abar_prev) * np.sqrt(1.0 - betas) / (1.0 - abar)
        variance = betas * (1.0 - abar_prev) / (1.0 - abar)
        if len(variance) > 1:
            log_var = np.log(np.concatenate([[variance[1]], variance[1:]]))
        else:
            log_var = np.log(np.maximum(variance, 1e-20))
        return c1, c2, log_var

    def q_sample(self, x0: np.ndarray, step: int, noise: np.ndarray) -> np.ndarray:
        """Noise x0 to chain step `step`."""
        abar = self.alphas_cumprod[step]
        return np.sqrt(abar) * x0 + np.sqrt(1.0 - abar) * noise
