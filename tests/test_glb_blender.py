"""A GLB sinmdm wrote, imported into Blender and exported again (tests/blender_roundtrip.py,
run by Blender's own Python), reads back as the original skeleton and motion: the same
joint names, parents, End Sites and offsets, and the same joints in the same places on
every frame, whether or not Blender was told to keep glTF extras (sinmdm's End Site and
up-axis marks), whatever rest orientations its bone heuristic gave the bones, and at
another scene frame rate (Blender resamples the keys).

Blender is the `bpy` module from PyPI (bpy 5.0.x, Python 3.11) in its own virtual
environment: SINMDM_BPY_PYTHON names its python, else /work/bpyenv/bin/python is used
when it exists (scripts/ci_blender.sh makes one); without either the tests skip."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from sinmdm.runtime.animation import animation_from_bvh, global_positions
from sinmdm.runtime.bvh import BVH, parse_bvh, read_bvh
from sinmdm.runtime.features import unit_scale
from sinmdm.runtime.rotations import matrix_to_quat

from .conftest import DEMO_CLIP, real_clip
from .layouts import LAYOUTS

pytest.importorskip("pygltflib")

ROUND_TRIP = Path(__file__).with_name("blender_roundtrip.py")
DEFAULT_BPY_PYTHON = Path("/work/bpyenv/bin/python")
# Blender keeps every transform in float32 and rebuilds each bone's rest from
# matrix products (its bone heuristic, then the exporter's inverse): measured, the
# offsets come back within 2.4e-7 of the figure's height and the joints' positions
# within 2.3e-6 (float32 ulps over a chain of joints). Lengths must agree to 1e-5
# of the height (0.02 mm on a 1.8 m figure) and positions to 1e-4 (0.2 mm), ten
# times below the 1e-3 at which an animator could see a difference.
OFFSET_TOLERANCE = 1e-5
POSITION_TOLERANCE = 1e-4
# Two bare End Sites, several ROOTs and a real joint named "A_end" with an End Site
# below it: a name-based End Site test must tell them apart.
SEVERAL_ROOTS = (
    "HIERARCHY\nROOT A\n{\nOFFSET 0 0 0\nCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
    "JOINT A_end\n{\nOFFSET 0 0.5 0\nCHANNELS 3 Zrotation Xrotation Yrotation\nEnd Site\n{\n}\n}\n}\n"
    "ROOT B\n{\nOFFSET 1 0 0\nCHANNELS 3 Yposition Xrotation Zrotation\nEnd Site\n{\nOFFSET 0 0.3 0\n}\n}\n"
    "MOTION\nFrames: 3\nFrame Time: 0.04\n"
    "0 1 0 10 20 30 5 0 0 0.5 45 10\n0 1 0 15 25 35 10 5 0 0.6 40 5\n0.1 1 0 20 30 40 15 10 5 0.7 35 0\n"
)


@pytest.fixture(scope="module")
def blender_python() -> Path:
    named = os.environ.get("SINMDM_BPY_PYTHON")
    if named:
        if not os.access(named, os.X_OK):
            pytest.skip(f"SINMDM_BPY_PYTHON={named} is not an executable")
        return Path(named)
    if DEFAULT_BPY_PYTHON.exists():
        return DEFAULT_BPY_PYTHON
    pytest.skip(f"no Blender Python: set SINMDM_BPY_PYTHON to a python with `pip install 'bpy==5.0.*'` "
                f"(scripts/ci_blender.sh), or create {DEFAULT_BPY_PYTHON}")


def short(bvh: BVH, frames: int) -> BVH:
    return BVH(bvh.skeleton, bvh.frame_time, bvh.values[:frames])


def clip(name: str) -> BVH:
    if name == "demo":
        return read_bvh(DEMO_CLIP)
    if name == "several-roots":
        return parse_bvh(SEVERAL_ROOTS)
    if name == "mixamo":  # Mixamo's "mixamorig7:" names, centimetres, 60 fps
        return short(read_bvh(real_clip("Joe_Walk-In-Circle.bvh")), 120)
    # A Z-up export with a static joint_Root at the floor (120 fps, ZYX rotations).
    return LAYOUTS["static-root-z-up"](short(read_bvh(real_clip("Xia_normal.bvh")), 120))


def through_blender(blender_python: Path, bvh: BVH, folder: Path, *options: str) -> tuple[dict, dict]:
    """read_glb of sinmdm's GLB of `bvh`, and of Blender's export of it."""
    from sinmdm.preview.gltf import read_glb, write_glb

    source = write_glb(bvh, folder / "sinmdm.glb")
    target = folder / "blender.glb"
    result = subprocess.run([str(blender_python), str(ROUND_TRIP), str(source), str(target), *options],
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0 and target.exists(), result.stdout[-2000:] + result.stderr[-2000:]
    return read_glb(source), read_glb(target)


def assert_same_skeleton(back: dict, bvh: BVH, height: float) -> None:
    skeleton, scale = bvh.skeleton, unit_scale(bvh.skeleton)
    assert back["names"] == list(skeleton.names)
    assert np.array_equal(back["parents"], skeleton.parents)
    assert np.abs(back["offsets"] - skeleton.offsets * scale).max() <= OFFSET_TOLERANCE * height
    assert [p for p, _ in back["end_sites"]] == [p for p, _ in skeleton.end_sites]
    for (_, offset), (_, theirs) in zip(back["end_sites"], skeleton.end_sites):
        expected = np.zeros(3) if theirs is None else theirs * scale
        assert np.abs(offset - expected).max() <= OFFSET_TOLERANCE * height


def figure_height(mine: dict) -> float:
    """The largest vertical extent of the joints on any frame, in glTF's Y-up world."""
    return float(np.ptp(mine["world_positions"][..., 1], axis=1).max())


CLIPS = [
    "demo",
    "several-roots",
    pytest.param("mixamo", marks=pytest.mark.realdata),
    pytest.param("z-up", marks=pytest.mark.realdata),
]


@pytest.mark.parametrize("extras", [True, False], ids=["extras", "no-extras"])
@pytest.mark.parametrize("name", CLIPS)
def test_blender_round_trip_gives_back_the_clip(tmp_path, blender_python, name, extras):
    bvh = clip(name)
    mine, back = through_blender(blender_python, bvh, tmp_path, *([] if extras else ["--no-extras"]))
    height = figure_height(mine)
    assert_same_skeleton(back, bvh, height)
    assert back["up_axis"] == mine["up_axis"]
    assert name != "z-up" or back["up_axis"] == "z"
    assert back["frames"] == bvh.frames and back["fps"] == pytest.approx(mine["fps"], rel=1e-6)
    assert np.abs(back["times"] - mine["times"]).max() < 1e-5
    # Same joints in the same places on every frame, in the skeleton's own frame
    # (what a BVH written from the result shows) and where a glTF viewer shows them.
    own = global_positions(animation_from_bvh(bvh)) * unit_scale(bvh.skeleton)
    assert np.abs(back["positions"] - own).max() <= POSITION_TOLERANCE * height
    assert np.abs(back["world_positions"] - mine["world_positions"]).max() <= POSITION_TOLERANCE * height
    # ... turned by the clip's own rotations (the rest pose is the BVH's again).
    dots = np.abs(np.sum(back["rotations"] * matrix_to_quat(animation_from_bvh(bvh).rotations), axis=-1))
    assert dots.min() > 1 - 1e-6


@pytest.mark.parametrize("heuristic", ["TEMPERANCE", "FORTUNE"])
def test_blender_bone_orientations_are_folded_back(tmp_path, blender_python, heuristic):
    """These heuristics export bones with rest rotations (pointing at a child),
    so the file's offsets and keys are in the bones' frames, not the skeleton's."""
    bvh = clip("demo")
    mine, back = through_blender(blender_python, bvh, tmp_path, "--no-extras", "--bone-heuristic", heuristic)
    height = figure_height(mine)
    assert_same_skeleton(back, bvh, height)
    own = global_positions(animation_from_bvh(bvh)) * unit_scale(bvh.skeleton)
    assert np.abs(back["positions"] - own).max() <= POSITION_TOLERANCE * height
    dots = np.abs(np.sum(back["rotations"] * matrix_to_quat(animation_from_bvh(bvh).rotations), axis=-1))
    assert dots.min() > 1 - 1e-6


def test_blender_resampled_at_its_scene_rate(tmp_path, blender_python):
    """A 30 fps clip in a 24 fps scene comes back with 24 fps keys over the same
    time span; every 4th of them falls on every 5th original frame."""
    bvh = clip("demo")
    assert round(1 / bvh.frame_time) == 30
    mine, back = through_blender(blender_python, bvh, tmp_path, "--no-extras", "--fps", "24")
    assert back["fps"] == 24.0 and back["frames"] == (bvh.frames - 1) * 24 // 30 + 1
    assert back["names"] == list(bvh.skeleton.names)
    shared = min((bvh.frames - 1) // 5, (back["frames"] - 1) // 4) + 1
    assert shared > 60
    error = np.abs(back["world_positions"][::4][:shared] - mine["world_positions"][::5][:shared]).max()
    assert error <= POSITION_TOLERANCE * figure_height(mine)


@pytest.mark.parametrize("layout", ["as-is", "static-root-z-up"])
def test_marks_dropped_without_blender(tmp_path, layout):
    """What Blender's default export does to sinmdm's marks, done here (no Blender
    needed): End Sites are known by their names, a Z-up skeleton by its stand-up turn."""
    import pygltflib

    from sinmdm.preview.gltf import read_glb, write_glb

    bvh = clip("demo") if layout == "as-is" else LAYOUTS[layout](clip("demo"))
    path = write_glb(bvh, tmp_path / "marked.glb")
    gltf = pygltflib.GLTF2().load_binary(str(path))
    assert any(node.extras for node in gltf.nodes)
    for node in gltf.nodes:
        node.extras = {}
    gltf.animations[0].extras = {}
    gltf.save_binary(str(tmp_path / "unmarked.glb"))
    mine, back = read_glb(path), read_glb(tmp_path / "unmarked.glb")
    assert back["names"] == mine["names"] == list(bvh.skeleton.names)
    assert np.array_equal(back["parents"], mine["parents"])
    assert [p for p, _ in back["end_sites"]] == [p for p, _ in bvh.skeleton.end_sites]
    assert back["up_axis"] == mine["up_axis"] == ("y" if layout == "as-is" else "z")
    assert back["fps"] == mine["fps"] and np.array_equal(back["positions"], mine["positions"])
