"""Top-down root paths of a clip and of samples, one panel per row of files: what a user sees
of a model's turning, beside the plausibility figures.

    python bench/root_paths.py CLIP --rows "world=a.bvh,b.bvh" "heading=c.bvh,d.bvh" --out docs/turning_walk.png
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("clip", type=Path)
    parser.add_argument("--rows", nargs="+", required=True, help="LABEL=FILE,FILE,...")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sinmdm.eval.plausibility import FPS, track
    from sinmdm.runtime import read_bvh
    from sinmdm.runtime.features import build_codec

    reference = read_bvh(args.clip)
    codec = build_codec(reference, fps=FPS)
    joint = reference.skeleton.names[codec.trajectory_joint]
    across = [a for a in range(3) if a != codec.up_axis]
    rows = [(label, files.split(",")) for label, files in (r.split("=", 1) for r in args.rows)]
    width = 1 + max(len(files) for _, files in rows)
    figure, axes = plt.subplots(len(rows), width, figsize=(2.4 * width, 2.4 * len(rows)), squeeze=False)
    for (label, files), line in zip(rows, axes):
        for ax, path in zip(line, [str(args.clip), *files]):
            positions = track(read_bvh(path), [joint], codec.scale).positions[:, 0][:, across]
            ax.plot(positions[:, 0], positions[:, 1], lw=1, color="#c0504d" if path == str(args.clip) else "#2f6db3")
            ax.plot(*positions[0], "o", color="#3a3", ms=3)
            ax.set_aspect("equal", adjustable="datalim")
            ax.set_title("clip" if path == str(args.clip) else f"{label}: {Path(path).stem}", fontsize=7)
            ax.tick_params(labelsize=6)
        for ax in line[1 + len(files):]:
            ax.axis("off")
    figure.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(args.out, dpi=90)


if __name__ == "__main__":
    main()
