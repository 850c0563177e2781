"""Training batches from one clip: the whole clip repeated (paper) or random
crops (cpu), with the paper's random time rescale."""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from .presets import TrainConfig


def rescale_time(clip: torch.Tensor, factor: float, multiple: int = 1) -> torch.Tensor:
    """(F, T) -> (F, T') with T' = floor(T * factor) floored to `multiple`, cubic."""
    length = max(multiple, int(math.floor(clip.shape[1] * factor / multiple)) * multiple)
    if length == clip.shape[1]:
        return clip
    resized = F.interpolate(clip[None, :, None, :], size=(1, length), mode="bicubic", align_corners=False)
    return resized[0, :, 0]


class BatchSampler:
    """Draws training batches (B, F, L) with a dedicated torch generator, so a run
    is reproducible from its seed and resumable from the generator's state."""

    def __init__(self, clip: torch.Tensor, config: TrainConfig, generator: torch.Generator):
        self.clip = clip
        self.config = config
        self.generator = generator

    @property
    def window(self) -> int:
        """The length the model is trained (and must be sampled) at."""
        frames = self.clip.shape[1]
        if self.config.crop is None:
            return frames - frames % 4
        return min(self.config.crop, frames)

    def __call__(self) -> torch.Tensor:
        config, clip = self.config, self.clip
        if config.rescale is not None:
            low, high = config.rescale
            factor = low + (high - low) * float(torch.rand((), generator=self.generator))
            clip = rescale_time(clip, factor, multiple=4 if config.crop is None else 1)
        if config.crop is None:
            clip = clip[:, : clip.shape[1] - clip.shape[1] % 4]
            return clip.unsqueeze(0).expand(config.batch, -1, -1).contiguous()
        length = min(config.crop, clip.shape[1])
        starts = torch.randint(0, clip.shape[1] - length + 1, (config.batch,), generator=self.generator)
        index = starts[:, None] + torch.arange(length)[None, :]
        return clip[:, index].permute(1, 0, 2).contiguous()
