"""Previews and glTF on production skeleton layouts (derived in code by tests/layouts.py
from a real clip): a static `joint_Root` at the floor above the hips, a Z-up export, and
both. The stick figure, the camera and the rendered GIF are the original clip's whatever
the layout; the GLB of a Z-up clip stands up in glTF's Y-up world, with the file's joints
and animation unchanged."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from sinmdm.runtime.animation import animation_from_bvh, global_positions
from sinmdm.runtime.bvh import BVH, read_bvh, write_bvh
from sinmdm.runtime.features import unit_scale
from sinmdm.runtime.rotations import matrix_to_quat
from sinmdm.runtime.rig import analyse_rig

from .conftest import real_clip, run_cli
from .layouts import LAYOUTS, with_static_root, z_up

CLIP = "Xia_normal.bvh"  # 120 fps, ZYX rotations, walks about 0.5 m along X
DERIVED = ["static-root", "z-up", "static-root-z-up", "armature"]
FIXED = {"static-root": ["joint_Root"], "static-root-z-up": ["joint_Root"], "armature": ["Armature"], "z-up": []}


@pytest.fixture(scope="module")
def original() -> BVH:
    return read_bvh(real_clip(CLIP))


@pytest.fixture(scope="module")
def original_figure(original):
    from sinmdm.preview import stick_figure

    return stick_figure(original)


def figure_size(figure) -> float:
    return float(np.ptp(figure.points.reshape(-1, 3), axis=0).max())


def rig_of(bvh: BVH):
    return analyse_rig(animation_from_bvh(bvh), unit_scale(bvh.skeleton))


# --------------------------------------------------------------------------- stick figure and camera


@pytest.mark.parametrize("layout", DERIVED)
def test_stick_figure_is_the_same_whatever_the_layout(original, original_figure, layout):
    from sinmdm.preview import stick_figure

    derived = LAYOUTS[layout](original)
    figure = stick_figure(derived)
    # The fixed joints are left out, so points, names and bones are the original's, one for one.
    assert figure.names == original_figure.names
    assert np.array_equal(figure.parents, original_figure.parents)
    assert figure.points.shape == original_figure.points.shape
    error = np.abs(figure.points - original_figure.points).max()
    assert error < 1e-6 * figure_size(original_figure), error
    # Y up in the preview: the head above the feet on every frame.
    head, feet = figure.names.index("Head"), [figure.names.index(n) for n in ("LeftFoot", "RightFoot")]
    height = np.median(np.ptp(figure.points[..., 1], axis=1))
    assert (figure.points[:, head, 1] > figure.points[:, feet, 1].max(axis=1) + 0.5 * height).all()


@pytest.mark.parametrize("layout", DERIVED)
def test_no_bone_reaches_a_fixed_joint(original, layout):
    from sinmdm.preview import stick_figure

    derived = LAYOUTS[layout](original)
    rig = rig_of(derived)
    names = derived.skeleton.names
    assert [names[j] for j in rig.fixed_joints] == FIXED[layout]
    figure = stick_figure(derived)
    assert not set(FIXED[layout]) & set(figure.names)
    bones = figure.bones
    assert len(bones) == len(figure.names) - 1  # one tree below the hips, nothing hangs from a dropped joint
    # No bone starts at the floor origin where joint_Root / Armature sits.
    parent_points = figure.points[:, bones[:, 1]]
    assert np.linalg.norm(parent_points, axis=-1).min() > 1e-3 * figure_size(figure)


@pytest.mark.parametrize("layout", DERIVED)
def test_camera_follows_the_hips(original, original_figure, layout):
    from sinmdm.preview import smooth_track, stick_figure
    from sinmdm.preview.render import panel_view

    figure = stick_figure(LAYOUTS[layout](original))
    assert figure.names[figure.root] == "Hips"
    rate = 40.0
    times = np.arange(int(figure.seconds * rate)) / rate
    view, reference = panel_view(figure, times, rate), panel_view(original_figure, times, rate)
    hips = figure.at(times)[:, figure.root]
    assert np.allclose(view.target[:, [0, 2]], smooth_track(hips[:, [0, 2]], rate), atol=1e-9)
    assert np.abs(view.target - reference.target).max() < 1e-6 * figure_size(figure)
    # The character walks away from the origin and the camera goes with it.
    travel = np.linalg.norm(view.target[-1] - view.target[0])
    assert travel > figure_size(figure) * 0.5
    assert np.linalg.norm(view.target[:, [0, 2]] - hips[:, [0, 2]], axis=1).max() < 0.25 * figure_size(figure)


def test_overrides_reach_the_stick_figure(original, original_figure):
    from sinmdm.preview import stick_figure
    from sinmdm.runtime.errors import SinMDMError

    derived = with_static_root(z_up(original))
    forced = stick_figure(derived, up="z", root="Hips")
    assert np.abs(forced.points - original_figure.points).max() < 1e-6 * figure_size(original_figure)
    lying = stick_figure(derived, up="y")  # wrongly told Y-up: the figure lies along Z, as before
    head, hips = lying.names.index("Head"), lying.names.index("Hips")
    assert np.abs(lying.points[:, head, 2] - lying.points[:, hips, 2]).min() > 0.1 * figure_size(lying)
    # --root joint_Root: told that the static root carries the motion, it stays in the figure.
    kept = stick_figure(derived, root="joint_Root")
    assert kept.names[kept.root] == "joint_Root" and len(kept.names) == len(original_figure.names) + 1
    with pytest.raises(SinMDMError, match="unknown up axis"):
        stick_figure(derived, up="x")


def test_viewer_data_is_the_same_whatever_the_layout(original):
    from sinmdm.preview import stick_figure
    from sinmdm.preview.viewer import viewer_data

    short = BVH(original.skeleton, original.frame_time, original.values[:120])
    mine = viewer_data([stick_figure(LAYOUTS["static-root-z-up"](short), "x")])
    theirs = viewer_data([stick_figure(short, "x")])
    assert mine["clips"][0]["parents"] == theirs["clips"][0]["parents"]
    assert np.abs(np.array(mine["clips"][0]["points"]) - np.array(theirs["clips"][0]["points"])).max() <= 1
    assert np.abs(np.array(mine["track"]["xz"]) - np.array(theirs["track"]["xz"])).max() <= 1


# --------------------------------------------------------------------------- glTF


@pytest.mark.parametrize("layout", ["z-up", "static-root-z-up", "static-root"])
def test_glb_stands_up_with_the_file_joints_and_animation(tmp_path, original, layout):
    pytest.importorskip("pygltflib")
    from sinmdm.preview.gltf import read_glb, write_glb

    derived = LAYOUTS[layout](original)
    back = read_glb(write_glb(derived, tmp_path / "clip.glb"))
    scale = unit_scale(derived.skeleton)
    assert back["names"] == list(derived.skeleton.names)
    assert back["up_axis"] == ("z" if "z-up" in layout else "y")
    # The joints and the animation are the file's own, untouched ...
    animation = animation_from_bvh(derived)
    own = global_positions(animation) * scale
    assert np.abs(back["positions"] - own).max() < 1e-4
    dots = np.abs(np.sum(back["rotations"] * matrix_to_quat(animation.rotations), axis=-1))
    assert dots.min() > 1 - 1e-6
    # ... and in the glTF world (Y up) they stand where the Y-up original stands.
    expected = global_positions(animation_from_bvh(original)) * unit_scale(original.skeleton)
    world = back["world_positions"][:, [back["names"].index(n) for n in original.skeleton.names]]
    assert np.abs(world - expected).max() < 1e-4
    head = back["names"].index("Head")
    feet = [back["names"].index(n) for n in ("LeftFoot", "RightFoot")]
    height = np.ptp(expected[..., 1])
    assert (back["world_positions"][:, head, 1] > back["world_positions"][:, feet, 1].max(axis=1) + 0.3 * height).all()


def test_glb_mesh_has_no_bone_from_the_static_root(tmp_path, original):
    pygltflib = pytest.importorskip("pygltflib")
    from sinmdm.preview.gltf import _read_accessor, write_glb

    derived = LAYOUTS["static-root-z-up"](original)
    path = write_glb(derived, tmp_path / "clip.glb")
    gltf = pygltflib.GLTF2().load_binary(str(path))
    top = [n for n in gltf.nodes if n.name == "skeleton"]
    assert len(top) == 1 and top[0].children == [0] and top[0].extras == {"sinmdm_up_axis": "z"}
    assert gltf.skins[0].skeleton == gltf.nodes.index(top[0])
    assert all(n.rotation is None for n in gltf.nodes if n is not top[0])  # joints keep identity rest rotations
    (primitive,) = gltf.meshes[0].primitives
    joints = _read_accessor(gltf, gltf.binary_blob(), primitive.attributes.JOINTS_0, path)[:, 0]
    assert 0 not in set(joints.astype(int).tolist())  # joint_Root carries no vertex


@pytest.mark.skipif(not os.environ.get("SINMDM_GLTF_VALIDATOR"),
                    reason="set SINMDM_GLTF_VALIDATOR to a folder where `npm install gltf-validator` ran")
def test_z_up_glb_passes_khronos_validator(tmp_path, original):
    from sinmdm.preview.gltf import write_glb

    short = BVH(original.skeleton, original.frame_time, original.values[:60])
    path = write_glb(LAYOUTS["static-root-z-up"](short), tmp_path / "zup.glb")
    script = tmp_path / "validate.js"
    script.write_text(
        "const v = require('gltf-validator'); const fs = require('fs');\n"
        "v.validateBytes(new Uint8Array(fs.readFileSync(process.argv[2])))"
        ".then(r => { console.log(JSON.stringify(r.issues));"
        " process.exit(r.issues.numErrors + r.issues.numWarnings ? 1 : 0); });\n"
    )
    env = dict(os.environ, NODE_PATH=str(Path(os.environ["SINMDM_GLTF_VALIDATOR"]) / "node_modules"))
    result = subprocess.run(["node", str(script), str(path)], capture_output=True, text=True, env=env, timeout=60)
    assert result.returncode == 0, result.stdout + result.stderr


# --------------------------------------------------------------------------- the real GIF, through the CLI


def gif_frames(path: Path) -> list[np.ndarray]:
    from PIL import Image

    with Image.open(path) as gif:
        frames = []
        for k in range(gif.n_frames):
            gif.seek(k)
            frames.append(np.asarray(gif.convert("RGB")))
    return frames


def test_cli_gif_of_static_root_z_up_clip_is_the_original_preview(tmp_path, original):
    pytest.importorskip("matplotlib")
    derived = tmp_path / "xia_static_root_z_up.bvh"
    write_bvh(derived, z_up(with_static_root(original)))
    args = ["--max-seconds", "1", "--labels", "walk", "--json"]
    mine, theirs = tmp_path / "derived.gif", tmp_path / "original.gif"
    for clip, out in ((derived, mine), (real_clip(CLIP), theirs)):
        result = run_cli("sinmdm-run", "preview", str(clip), "--out", str(out), *args)
        assert result.returncode == 0, result.stderr
        assert json.loads(result.stdout)["frames"] == 40
    a, b = gif_frames(mine), gif_frames(theirs)
    assert len(a) == len(b) == 40
    for frame_a, frame_b in zip(a, b):  # the BVH text rounds to 6 digits: a pixel or two may differ
        assert (frame_a != frame_b).any(axis=-1).sum() < 50

    # The figure stands: its ink is taller than wide, in the middle of the panel.
    from sinmdm.preview import CLIP_COLOURS

    target = np.array([int(CLIP_COLOURS[0][k:k + 2], 16) for k in (1, 3, 5)])
    ink = np.linalg.norm(a[20].astype(float) - target, axis=-1) < 60
    ink[:30] = False  # the label band
    rows, columns = np.nonzero(ink)
    assert ink.sum() > 300
    assert np.ptp(rows) > 1.3 * np.ptp(columns)
    assert abs(columns.mean() - ink.shape[1] / 2) < ink.shape[1] / 5

    forced = run_cli("sinmdm-run", "preview", str(derived), "--out", str(tmp_path / "forced.gif"),
                     "--up", "z", "--root", "Hips", *args)
    assert forced.returncode == 0, forced.stderr
    assert all((f != g).any(axis=-1).sum() < 50 for f, g in zip(gif_frames(tmp_path / "forced.gif"), a))


def test_cli_preview_refuses_a_bad_up_or_root(tmp_path, original):
    derived = tmp_path / "clip.bvh"
    write_bvh(derived, with_static_root(BVH(original.skeleton, original.frame_time, original.values[:10])))
    bad_up = run_cli("sinmdm-run", "preview", str(derived), "--out", str(tmp_path / "x.gif"), "--up", "x")
    assert bad_up.returncode == 2 and "unknown up axis" in bad_up.stderr
    bad_root = run_cli("sinmdm-run", "preview", str(derived), "--out", str(tmp_path / "x.gif"), "--root", "Nope")
    assert bad_root.returncode == 2 and bad_root.stderr.startswith("error:")
    assert not (tmp_path / "x.gif").exists()
