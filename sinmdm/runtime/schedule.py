"""The cosine noise schedule and the DDPM posterior (float64); the single source
of truth for training, export metadata and sampling."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

NUM_TIMESTEPS = 1000
UPDATE_FRAMES = 4096  # frames per block of the DDPM update


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
        abar = float(self.alphas_cumprod[step])  # a Python float keeps the arrays' dtype
        return math.sqrt(abar) * x0 + math.sqrt(1 - abar) * noise

    def ddpm_step(self, step: int, x: np.ndarray, x0: np.ndarray, noise: np.ndarray | None,
                  out: np.ndarray | None = None) -> np.ndarray:
        """x at chain step `step` - 1 from x at `step` and the predicted x0: the posterior mean,
        plus its fixed-small noise except at the last step (respaced chains: the same formula
        on the respaced coefficients). `out` may be `x` itself when the caller owns it."""
        c1, c2, log_var = self._posterior
        a, b = float(c1[step]), float(c2[step])  # Python floats keep the state's dtype (float32 or float64)
        sigma = math.exp(0.5 * float(log_var[step])) if step > 0 else None
        out = np.empty_like(x0, shape=x.shape) if out is None else out
        # a block of frames at a time: a long motion holds no temporary the size of its state
        for first in range(0, x.shape[-1], UPDATE_FRAMES):
            block = (..., slice(first, first + UPDATE_FRAMES))
            mean = a * x0[block]
            mean += b * x[block]
            if sigma is not None:
                mean += sigma * noise[block]
            out[block] = mean
        return out

    def ddim_step(self, step: int, x: np.ndarray, x0: np.ndarray, eta: float, noise: np.ndarray | None) -> np.ndarray:
        """DDIM's update (Song et al. eq. 12); `eta` 0 is deterministic, 1 is DDPM-like."""
        abar = float(self.alphas_cumprod[step])  # Python floats keep the state's dtype
        abar_prev = float(self.alphas_cumprod[step - 1]) if step > 0 else 1.0
        eps = (x - math.sqrt(abar) * x0) / math.sqrt(1.0 - abar)
        sigma = eta * math.sqrt((1 - abar_prev) / (1 - abar) * (1 - abar / abar_prev))
        x = math.sqrt(abar_prev) * x0 + math.sqrt(max(1 - abar_prev - sigma**2, 0.0)) * eps
        if step > 0 and sigma > 0:
            x = x + sigma * noise
        return x

    @cached_property
    def _posterior(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.posterior()
