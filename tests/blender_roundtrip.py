"""Import a GLB into Blender and export it again, as an animator would.

Run by Blender's own Python (the `bpy` module from PyPI), never by the project's:

    /work/bpyenv/bin/python tests/blender_roundtrip.py IN.glb OUT.glb
        [--no-extras] [--fps N] [--bone-heuristic BLENDER|TEMPERANCE|FORTUNE]

Factory settings, the glTF importer's defaults (Blender's bone heuristic, so the
bones get Blender's rest orientations), then the exporter's defaults with the
animation baked at every frame, +Y up and custom properties written back as
extras (`--no-extras`: the exporter's default, which drops them). The scene's
frame rate is set to the clip's first, as an animator does: the importer turns
key times into frames at the scene's rate and the exporter samples whole frames,
so at Blender's default 24 fps a 30 fps clip comes back resampled (`--fps 24`
does that on purpose).
"""

from __future__ import annotations

import argparse
import json
import struct

import bpy


def clip_fps(path: str) -> float | None:
    """The frame rate sinmdm stores in the first animation's extras, else the
    spacing of that animation's first time accessor; None without either."""
    with open(path, "rb") as fh:
        data = fh.read()
    length, kind = struct.unpack_from("<II", data, 12)
    if kind != 0x4E4F534A:  # the GLB's first chunk must be its JSON
        return None
    gltf = json.loads(data[20:20 + length])
    animations = gltf.get("animations") or []
    if not animations:
        return None
    fps = (animations[0].get("extras") or {}).get("fps")
    if fps:
        return float(fps)
    times = gltf["accessors"][animations[0]["samplers"][0]["input"]]
    count, last = times.get("count", 0), (times.get("max") or [0.0])[0]
    return (count - 1) / last if count > 1 and last > 0 else None


def set_scene_fps(fps: float) -> None:
    render = bpy.context.scene.render  # Blender plays at fps / fps_base
    render.fps = max(1, round(fps))
    render.fps_base = render.fps / fps


def round_trip(source: str, target: str, extras: bool, fps: float | None, bone_heuristic: str) -> None:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    fps = fps or clip_fps(source)
    if fps:
        set_scene_fps(fps)
    bpy.ops.import_scene.gltf(filepath=source, bone_heuristic=bone_heuristic)
    bpy.ops.export_scene.gltf(
        filepath=target,
        export_format="GLB",
        export_yup=True,
        export_animations=True,
        export_bake_animation=True,
        export_force_sampling=True,
        export_frame_step=1,
        export_extras=extras,
    )


def main() -> None:
    parser = argparse.ArgumentParser(description="Import a GLB into Blender and export it again.")
    parser.add_argument("source")
    parser.add_argument("target")
    parser.add_argument("--no-extras", action="store_true", help="drop custom properties (the exporter's default)")
    parser.add_argument("--fps", type=float, help="the scene's frame rate (default: the clip's)")
    parser.add_argument("--bone-heuristic", default="BLENDER", choices=("BLENDER", "TEMPERANCE", "FORTUNE"))
    args = parser.parse_args()
    round_trip(args.source, args.target, not args.no_extras, args.fps, args.bone_heuristic)


if __name__ == "__main__":
    main()
