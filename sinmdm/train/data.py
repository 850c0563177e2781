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


# Crops of 64 frames shook the two short Xia clips (82 and 90 frames): trained whole, as the paper
# trains every clip, they shook less (jitter 2.9x -> 2.1x and 2.1x -> 1.5x the clip's, plausible
# samples 1 -> 8 and 8 -> 19 of 20) at the same coverage; on longer clips crops of 96 changed
# nothing beyond the seed spread at 1.5x the cost (BENCHMARKS.md, "Crop length, EMA ...").
def choose_crop(frames: int, config: TrainConfig) -> tuple[int | None, str]:
    """(frames per training example or None for the paper's whole-clip batch, why) for a clip
    of `frames` frames."""
    if config.crop is None:
        return None, "the whole clip, rescaled in time (the paper)"
    if config.whole_clip_frames and frames <= config.whole_clip_frames:
        return frames, f"the whole clip: it has at most {config.whole_clip_frames} frames"
    if frames <= config.crop:
        return frames, f"the whole clip: it is not longer than the crop of {config.crop}"
    if config.crop_edges > 0:
        return config.crop, f"random crops of {config.crop} frames, starts up to {config.crop_edges:g} of a crop off the clip's ends"
    return config.crop, f"random crops of {config.crop} frames"


def crop_starts(frames: int, length: int, edges: float, count: int, generator: torch.Generator) -> torch.Tensor:
    """`count` crop starts in [0, frames - length]. Uniform starts put a clip's first frame in one
    crop position of `frames - length + 1` (its middle frames in `length`): drawn up to
    `edges * length` frames off either end and clamped in, the end crops are drawn that many times
    more often, and at edges 0.25 every 30-frame window near the ends is trained on about as
    often, on average, as one in the middle."""
    reach = int(round(edges * length))
    starts = torch.randint(-reach, frames - length + reach + 1, (count,), generator=generator)
    return starts.clamp(0, frames - length)


class BatchSampler:
    """Draws training batches (B, F, L) with a dedicated torch generator, so a run
    is reproducible from its seed and resumable from the generator's state."""

    def __init__(self, clip: torch.Tensor, config: TrainConfig, generator: torch.Generator):
        self.clip = clip
        self.config = config
        self.generator = generator
        self.crop, self.crop_why = choose_crop(clip.shape[1], config)

    @property
    def window(self) -> int:
        """The length the model is trained (and must be sampled) at."""
        frames = self.clip.shape[1]
        return frames - frames % 4 if self.crop is None else self.crop

    def __call__(self) -> torch.Tensor:
        config, clip = self.config, self.clip
        if config.rescale is not None:
            low, high = config.rescale
            factor = low + (high - low) * float(torch.rand((), generator=self.generator))
            clip = rescale_time(clip, factor, multiple=4 if self.crop is None else 1)
        if self.crop is None:
            clip = clip[:, : clip.shape[1] - clip.shape[1] % 4]
            return clip.unsqueeze(0).expand(config.batch, -1, -1).contiguous()
        length = min(self.crop, clip.shape[1])
        starts = crop_starts(clip.shape[1], length, config.crop_edges, config.batch, self.generator)
        index = starts[:, None] + torch.arange(length)[None, :]
        return clip[:, index].permute(1, 0, 2).contiguous()
