"""Features <-> the space a model's graph is trained and sampled in: the paper's features,
optionally with the root velocity per second (`model_scale`) and seen from the character's
heading (`heading.HeadingFrame`). Training, the sampler and the golden vectors all go
through this one type, so a model's metadata says once how its graph sees motion."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .features import MotionCodec, model_scale
from .heading import HeadingFrame


@dataclass(frozen=True)
class GraphSpace:
    feature_width: int
    scale: np.ndarray | None = None  # (F,) features -> graph factors, None: all 1
    heading: HeadingFrame | None = None

    @property
    def width(self) -> int:
        return self.feature_width + (self.heading is not None)

    @property
    def graph_scale(self) -> np.ndarray | None:
        """(width,) the scale over the graph's channels (the turn rate is never scaled)."""
        if self.scale is None or self.heading is None:
            return self.scale
        return np.concatenate([self.scale, [1.0]])

    def to_graph(self, features: np.ndarray) -> np.ndarray:
        """(..., T, F) features -> (..., T, width) float64."""
        x = np.asarray(features, dtype=np.float64)
        if self.heading is not None:
            x = self.heading.to_graph(x)
        if self.scale is not None:
            x = x.copy()
            x[..., : self.feature_width] *= self.scale
        return x

    def to_features(self, x: np.ndarray, starts: np.ndarray | None = None) -> np.ndarray:
        """(..., T, width) -> (..., T, F) float64; `starts`: the heading frame's start headings."""
        x = np.asarray(x, dtype=np.float64)
        if self.scale is not None:
            x = x.copy()
            x[..., : self.feature_width] /= self.scale
        return x if self.heading is None else self.heading.to_features(x, starts)


def graph_space(codec: MotionCodec, metadata: dict) -> GraphSpace:
    """The space a model's metadata (`velocity_unit`, `heading_frame`) says its graph works in."""
    frame = metadata.get("heading_frame")
    heading = None if frame is None else HeadingFrame.of(codec, frame["forward"], frame["start"])
    return GraphSpace(codec.width, model_scale(codec, metadata.get("velocity_unit", "frame")), heading)
