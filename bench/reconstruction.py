"""How well a trained denoiser gives back its own clip at low noise, and what that does to the
feet: the x0 prediction's mean squared error and its planted contact joints' speed (root mean
square, in contact speeds per frame; the foot-contact loss's measure) at several noise levels.

    python bench/reconstruction.py --run runs/X/CLIP --clip ../shared/motions/CLIP.bvh

Needs torch (the training extra).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from sinmdm.runtime.graph_space import graph_space  # noqa: E402
from sinmdm.train.diffusion import GaussianDiffusion  # noqa: E402
from sinmdm.train.foot_loss import FootContactLoss  # noqa: E402
from sinmdm.train.presets import TrainConfig  # noqa: E402
from sinmdm.train.trainer import graph_metadata, load_clip, load_trained_model  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", type=Path, required=True)
    parser.add_argument("--clip", type=Path, required=True)
    parser.add_argument("--batch", type=int, default=16)
    args = parser.parse_args()
    model, config = load_trained_model(args.run)
    train_config = TrainConfig.from_dict(config["train"])
    clip = load_clip(args.clip, train_config.fps, {})
    space = graph_space(clip.codec, graph_metadata(clip, train_config))
    x = torch.from_numpy(np.ascontiguousarray(space.to_graph(clip.features).T, dtype=np.float32))
    window = config["window"]
    foot = FootContactLoss(clip.codec, space.scale, heading=space.heading is not None)
    diffusion, generator = GaussianDiffusion(), torch.Generator().manual_seed(0)
    with torch.no_grad():
        starts = torch.randint(0, x.shape[1] - window + 1, (args.batch,), generator=generator)
        batch = torch.stack([x[:, s : s + window] for s in starts])
        print(f"the clip itself: planted speed {foot(batch, batch) ** 0.5:.3f} contact speeds per frame")
        for t in (1, 10, 100, 400, 700, 999):
            steps = torch.full((args.batch,), t)
            noise = torch.randn(batch.shape, generator=generator)
            prediction = model(diffusion.q_sample(batch, steps, noise), steps)
            mse = float(((prediction - batch) ** 2).mean())
            print(f"t {t:4d}: x0 error {mse:.4f}, planted speed {float(foot(prediction, batch)) ** 0.5:.2f} contact speeds per frame")


if __name__ == "__main__":
    main()
