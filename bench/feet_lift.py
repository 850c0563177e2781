"""How high the feet lift, drawn: the contact joints' height over time for a clip and the first
sample of each folder, one strip each on one scale, with the plausibility metric's lift beside it
(its 95th height percentile above its 5th, against the clip's). What an animator sees as a shuffle.

    python bench/feet_lift.py CLIP.bvh RUN/samples_default OTHER_RUN/samples_default --out docs/feet_lift.png
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def main() -> None:
    from PIL import Image, ImageDraw

    from sinmdm.eval.plausibility import plausibility
    from sinmdm.runtime import read_bvh
    from sinmdm.runtime.features import build_codec
    from sinmdm.preview import stick_figure

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("clip", type=Path)
    parser.add_argument("folders", type=Path, nargs="+")
    parser.add_argument("--labels", default=None, help="comma-separated, one per folder")
    parser.add_argument("--seconds", type=float, default=12.0, help="seconds drawn per strip")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()

    clip = read_bvh(args.clip)
    codec = build_codec(clip, fps=30.0)
    names = [clip.skeleton.names[j] for j in codec.contact_joints]
    labels = args.labels.split(",") if args.labels else [str(f) for f in args.folders]
    strips = [("clip", stick_figure(clip))]
    for folder, label in zip(args.folders, labels):
        files = sorted(folder.glob("*.bvh"))
        aggregate = plausibility(clip, [read_bvh(f) for f in files])["aggregate"]
        ratio = aggregate["foot_lift_cm"] / aggregate["clip_foot_lift_cm"]
        strips.append((f"{label}: lift {ratio:.2f}x the clip's over {len(files)} samples", stick_figure(read_bvh(files[0]))))
        print(f"{label}: feet lift {aggregate['foot_lift_cm']:.1f} cm, the clip's {aggregate['clip_foot_lift_cm']:.1f} "
              f"({ratio:.2f}x), {aggregate['implausible']} of {len(files)} implausible")
    width, height = 1200, 150
    image = Image.new("RGB", (width, height * len(strips)), "white")
    draw = ImageDraw.Draw(image)
    def heights(figure):
        index = [figure.names.index(n) for n in names if n in figure.names]
        return figure.points[:int(args.seconds * figure.fps), index, 1]
    top = max(float(np.percentile(heights(f), 99.5)) for _, f in strips) * 1.1
    bottom = min(float(heights(f).min()) for _, f in strips)
    colours = [(200, 40, 40), (40, 40, 200), (40, 150, 40), (160, 100, 0)]
    for row, (label, figure) in enumerate(strips):
        y0 = row * height
        values = heights(figure)
        frames = int(args.seconds * figure.fps)
        for k in range(values.shape[1]):
            points = [(10 + t * (width - 20) / frames, y0 + height - 8 - (v - bottom) / (top - bottom) * (height - 30))
                      for t, v in enumerate(values[:, k])]
            draw.line(points, fill=colours[k % len(colours)], width=2)
        draw.text((12, y0 + 4), f"{label} ({', '.join(names[:2])}{'...' if len(names) > 2 else ''}, first {args.seconds:.0f} s)",
                  fill=(0, 0, 0))
        draw.line([(0, y0 + height - 1), (width, y0 + height - 1)], fill=(200, 200, 200))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    image.save(args.out)


if __name__ == "__main__":
    main()
