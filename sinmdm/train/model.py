"""The SinMDM denoiser: a one-level 1-D UNet over time with QnA local attention.

Tensors are laid out (batch, features F, frames T); the network predicts the clean
motion x0 from (x_t, t). Every op is chosen to export to ONNX for any T >= 1:
no einsum, no shape-dependent padding, no data-dependent control flow, and a
hand-written GroupNorm so the graph holds no GroupNormalization op.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any

import torch
import torch.nn.functional as F
from torch import Tensor, nn

NORM_KINDS = ("group", "frame")
CONV_KERNEL = 3


@dataclass
class ModelConfig:
    """Hyper-parameters of the denoiser; the defaults are the paper's configuration."""

    features: int
    width: int = 256
    time_embed_dim: int = 256
    heads: int = 4
    attention_window: int = 3  # frames each QnA query sees (not the training crop)
    groups: int = 32
    dropout: float = 0.5
    # "group": GroupNorm statistics over channels-in-group x all frames (faithful).
    # "frame": the same groups, statistics per frame (experimental; length-independent).
    norm: str = "group"

    def __post_init__(self) -> None:
        if self.features < 1:
            raise ValueError("features must be >= 1")
        if self.width % self.heads:
            raise ValueError(f"width {self.width} is not divisible by heads {self.heads}")
        if self.width % self.groups:
            raise ValueError(f"width {self.width} is not divisible by groups {self.groups}")
        if self.attention_window < 1 or self.attention_window % 2 == 0:
            raise ValueError(f"attention_window must be odd and >= 1, got {self.attention_window}")
        if self.time_embed_dim % 2:
            raise ValueError("time_embed_dim must be even")
        if self.norm not in NORM_KINDS:
            raise ValueError(f"norm must be one of {NORM_KINDS}, got {self.norm!r}")

    @property
    def embed_width(self) -> int:
        """Width of the time-embedding MLP output (4 x width)."""
        return 4 * self.width

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "ModelConfig":
        if "window" in data:  # runs written before the attention span had its own name
            data = {("attention_window" if k == "window" else k): v for k, v in data.items()}
        known = {f.name for f in fields(cls)}
        unknown = set(data) - known
        if unknown:
            raise ValueError(f"unknown model config keys: {sorted(unknown)}")
        return cls(**data)


def timestep_embedding(t: Tensor, dim: int, dtype: torch.dtype = torch.float32,
                       max_period: float = 10000.0) -> Tensor:
    """Sinusoidal embedding of raw timesteps (B,) -> (B, dim): cosine half first, then sine."""
    half = dim // 2
    freqs = torch.exp(-math.log(max_period) / half * torch.arange(half, dtype=dtype, device=t.device))
    args = t.to(dtype).unsqueeze(1) * freqs.unsqueeze(0)
    return torch.cat([torch.cos(args), torch.sin(args)], dim=-1)


class GroupNorm(nn.Module):
    """GroupNorm written with reshape/var_mean ops (equal to nn.GroupNorm up to
    rounding) so the export contains no GroupNormalization / InstanceNormalization op.

    With `per_frame=True` the statistics cover only the channels of a group at one
    frame, so the normalisation no longer couples distant frames.
    """

    def __init__(self, groups: int, channels: int, eps: float = 1e-5, per_frame: bool = False) -> None:
        super().__init__()
        if channels % groups:
            raise ValueError(f"{channels} channels do not split into {groups} groups")
        self.groups = groups
        self.channels = channels
        self.eps = eps
        self.per_frame = per_frame
        self.weight = nn.Parameter(torch.ones(channels))
        self.bias = nn.Parameter(torch.zeros(channels))

    def forward(self, x: Tensor, scale: Tensor | None = None, shift: Tensor | None = None) -> Tensor:
        """GN(x); given (B, C) `scale` and `shift`, GN(x) * (1 + scale) + shift.

        The normalisation, the affine and the modulation are folded into one
        per-channel multiply-add, so the full-size tensor is touched only twice.
        """
        # Like nn.GroupNorm under autocast, normalise half-precision inputs in float32.
        if x.dtype in (torch.float16, torch.bfloat16):
            x = x.float()
        batch, per_group = x.shape[0], self.channels // self.groups
        grouped = x.reshape(batch, self.groups, per_group, -1)  # (B, G, C/G, T)
        if self.per_frame:
            # Two passes, not var_mean: torch's var_mean over a middle dimension is ~40x slower on
            # CPU (a per-frame check of the walk took 9.4 s against 3.1 s under GroupNorm)
            mean = grouped.mean(dim=2, keepdim=True)
            centred = grouped - mean
            var = (centred * centred).mean(dim=2, keepdim=True)
        else:
            var, mean = torch.var_mean(grouped, dim=(2, 3), correction=0, keepdim=True)
        gain = self.weight.reshape(self.groups, per_group, 1)
        offset = self.bias.reshape(self.groups, per_group, 1)
        if (scale is None) != (shift is None):
            raise ValueError("scale and shift go together")
        if scale is not None and shift is not None:
            modulation = 1 + scale.reshape(batch, self.groups, per_group, 1)
            gain = gain * modulation
            offset = offset * modulation + shift.reshape(batch, self.groups, per_group, 1)
        multiplier = torch.rsqrt(var + self.eps) * gain
        return torch.addcmul(offset - mean * multiplier, grouped, multiplier).reshape(batch, self.channels, -1)

    def extra_repr(self) -> str:
        return f"{self.groups}, {self.channels}, eps={self.eps}, per_frame={self.per_frame}"


def make_norm(config: ModelConfig, channels: int) -> GroupNorm:
    return GroupNorm(config.groups, channels, per_frame=config.norm == "frame")


def conv3(in_channels: int, out_channels: int) -> nn.Conv1d:
    return nn.Conv1d(in_channels, out_channels, CONV_KERNEL, padding=CONV_KERNEL // 2)


def zero_init(module: nn.Module) -> nn.Module:
    for p in module.parameters():
        nn.init.zeros_(p)
    return module


class ResBlock(nn.Module):
    """GN -> SiLU -> Conv; GN(h) * (1 + scale) + shift from the time embedding ->
    SiLU -> Dropout -> zero-initialised Conv; plus an identity or 1x1 skip."""

    def __init__(self, config: ModelConfig, in_channels: int, out_channels: int) -> None:
        super().__init__()
        self.in_norm = make_norm(config, in_channels)
        self.in_conv = conv3(in_channels, out_channels)
        self.emb_proj = nn.Linear(config.embed_width, 2 * out_channels)
        self.out_norm = make_norm(config, out_channels)
        self.dropout = nn.Dropout(config.dropout)
        self.out_conv = zero_init(conv3(out_channels, out_channels))
        self.skip = nn.Identity() if in_channels == out_channels else nn.Conv1d(in_channels, out_channels, 1)

    def forward(self, x: Tensor, emb: Tensor) -> Tensor:
        h = self.in_conv(F.silu(self.in_norm(x)))
        projected = self.emb_proj(F.silu(emb))
        half = projected.shape[1] // 2  # slices, not chunk(): Split has no opset 18 -> 17 adapter
        scale, shift = projected[:, :half], projected[:, half:]
        h = self.out_norm(h, scale, shift)  # GN(h) * (1 + scale) + shift
        h = self.out_conv(self.dropout(F.silu(h)))
        return self.skip(x) + h


class QnA(nn.Module):
    """Learned-query local attention over `span` frames around each frame.

    One learned query per head; softmax over the window (frames outside the
    sequence excluded) of q . k_j + r[j - t + p], weighting the values v_j.
    """

    def __init__(self, channels: int, heads: int, span: int) -> None:
        super().__init__()
        self.channels = channels
        self.heads = heads
        self.head_dim = channels // heads
        self.span = span
        std = math.sqrt(1.0 / self.head_dim)
        self.query = nn.Parameter(torch.randn(heads, self.head_dim) * std)
        self.key_weight = nn.Parameter(torch.randn(channels, channels) * std)  # (C_in, heads * d)
        self.key_bias = nn.Parameter(torch.zeros(channels))
        self.rel_pos_bias = nn.Parameter(torch.zeros(heads, span))
        self.to_value = nn.Conv1d(channels, channels, 1)
        self.to_out = nn.Conv1d(channels, channels, 1)

    def logits(self, x: Tensor) -> Tensor:
        """s_h[j] = q_h . (Wk_h^T x_j + b_h) as one 1x1 projection C_in -> heads: (B, heads, T)."""
        q = self.query / (self.query.norm(dim=-1, keepdim=True) + 1e-6) / math.sqrt(self.head_dim)
        weight = (self.key_weight.reshape(self.channels, self.heads, self.head_dim) * q).sum(-1)  # (C_in, heads)
        bias = (self.key_bias.reshape(self.heads, self.head_dim) * q).sum(-1)  # (heads,)
        return F.conv1d(x, weight.t().unsqueeze(2), bias)

    def forward(self, x: Tensor) -> Tensor:
        batch = x.shape[0]
        scores = self.logits(x)
        # Softmax is shift-invariant; a per-(batch, head) max keeps exp from overflowing.
        # (A window whose logits all sit > ~87 below that max would underflow to 0/0;
        # the clamp below turns that degenerate case into a zero output instead of NaN.)
        weights = torch.exp(scores - scores.amax(dim=2, keepdim=True).detach())  # (B, heads, T)
        values = self.to_value(x).reshape(batch, self.heads, self.head_dim, -1)
        weighted = (values * weights.unsqueeze(2)).reshape(batch, self.channels, -1)

        # Window sums as depthwise convolutions with kernels exp(r); zero padding
        # means frames outside the sequence contribute nothing (are excluded).
        head_kernel = torch.exp(self.rel_pos_bias).unsqueeze(1)  # (heads, 1, k)
        channel_kernel = head_kernel.expand(self.heads, self.head_dim, self.span).reshape(
            self.channels, 1, self.span)
        pad = self.span // 2
        numerator = F.conv1d(weighted, channel_kernel, padding=pad, groups=self.channels)
        denominator = F.conv1d(weights, head_kernel, padding=pad, groups=self.heads)
        denominator = denominator.clamp_min(torch.finfo(denominator.dtype).tiny)
        attended = numerator.reshape(batch, self.heads, self.head_dim, -1) / denominator.unsqueeze(2)
        return self.to_out(attended.reshape(batch, self.channels, -1))


class QnABlock(nn.Module):
    """y = x + QnA(GN(x))."""

    def __init__(self, config: ModelConfig, channels: int) -> None:
        super().__init__()
        self.norm = make_norm(config, channels)
        self.attn = QnA(channels, config.heads, config.attention_window)

    def forward(self, x: Tensor) -> Tensor:
        return x + self.attn(self.norm(x))


class ResQnABlock(nn.Module):
    """A ResBlock followed by a QnA block."""

    def __init__(self, config: ModelConfig, in_channels: int, out_channels: int) -> None:
        super().__init__()
        self.res = ResBlock(config, in_channels, out_channels)
        self.qna = QnABlock(config, out_channels)

    def forward(self, x: Tensor, emb: Tensor) -> Tensor:
        return self.qna(self.res(x, emb))


class Denoiser(nn.Module):
    """x0_hat = Denoiser(x_t, t); the paper's one-level UNet (no down-sampling).

    in conv -> h0; input_block(h0) -> h1; output_block1(h1) -> h2;
    output_block2(concat(h2, h0)) -> out norm -> SiLU -> zero-initialised out conv.
    """

    def __init__(self, config: ModelConfig) -> None:
        super().__init__()
        self.config = config
        width, embed_width = config.width, config.embed_width
        self.time_embed = nn.Sequential(
            nn.Linear(config.time_embed_dim, embed_width),
            nn.SiLU(),
            nn.Linear(embed_width, embed_width),
        )
        self.in_conv = conv3(config.features, width)
        self.input_block = ResQnABlock(config, width, width)
        self.output_block1 = ResQnABlock(config, width, width)
        self.output_block2 = ResQnABlock(config, 2 * width, width)
        self.out_norm = make_norm(config, width)
        self.out_conv = zero_init(conv3(width, config.features))

    def forward(self, x_t: Tensor, t: Tensor) -> Tensor:
        """x_t: (B, F, T) float; t: (B,) original timesteps 0..999 (int or float)."""
        emb = self.time_embed(timestep_embedding(t, self.config.time_embed_dim, dtype=x_t.dtype))
        h0 = self.in_conv(x_t)
        h1 = self.input_block(h0, emb)
        h2 = self.output_block1(h1, emb)
        h3 = self.output_block2(torch.cat([h2, h0], dim=1), emb)
        return self.out_conv(F.silu(self.out_norm(h3)))


def receptive_field(config: ModelConfig) -> int:
    """Frames of input that can reach one output frame, ignoring GroupNorm statistics
    (exact for norm="frame"); 23 for the paper configuration."""
    conv, qna = CONV_KERNEL, config.attention_window
    res_block = [conv, conv]
    # Mirrors Denoiser.forward: in conv, three (ResBlock, QnA) pairs, out conv.
    kernels = [conv] + (res_block + [qna]) * 3 + [conv]
    return 1 + sum(k - 1 for k in kernels)


def count_parameters(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())
