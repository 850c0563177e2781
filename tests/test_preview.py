"""Previews: GIF/MP4 renders, the HTML viewer in headless Chromium, GLB export and read-back."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sinmdm.runtime.animation import animation_from_bvh, global_positions
from sinmdm.runtime.bvh import BVH, read_bvh
from sinmdm.runtime.errors import SinMDMError
from sinmdm.runtime.features import unit_scale

from .conftest import DEMO_CLIP, real_clip, run_cli

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_FLAGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync", "--hide-scrollbars",
]


def first_frames(bvh: BVH, count: int, start: int = 0) -> BVH:
    return BVH(bvh.skeleton, bvh.frame_time, bvh.values[start:start + count], bvh.path)


@pytest.fixture(scope="module")
def demo() -> BVH:
    return read_bvh(DEMO_CLIP)


def colour_pixels(rgb: np.ndarray, colour: str, tolerance: float = 60.0) -> np.ndarray:
    """Mask of the pixels close to a #rrggbb colour."""
    target = np.array([int(colour[k:k + 2], 16) for k in (1, 3, 5)], dtype=np.float64)
    return np.linalg.norm(rgb[..., :3].astype(np.float64) - target, axis=-1) < tolerance


# --------------------------------------------------------------------------- GIF / MP4


def test_gif_has_one_frame_per_clip_frame(tmp_path, demo):
    pytest.importorskip("matplotlib")
    from PIL import Image

    from sinmdm.preview.render import render_preview

    info = render_preview([first_frames(demo, 60)], tmp_path / "clip.gif")
    assert (info.frames, info.fps, info.size) == (60, 30.0, (360, 360))
    with Image.open(tmp_path / "clip.gif") as gif:
        assert gif.n_frames == 60 and gif.size == (360, 360)
        durations = []
        for k in range(gif.n_frames):
            gif.seek(k)
            durations.append(gif.info["duration"])
    assert sum(durations) == 2000  # 60 frames at 30 fps, centisecond delays alternating 30/40 ms
    assert set(durations) <= {30, 40}


def test_mp4_has_one_frame_per_clip_frame(tmp_path, demo):
    imageio_ffmpeg = pytest.importorskip("imageio_ffmpeg")
    pytest.importorskip("matplotlib")
    from sinmdm.preview.render import render_preview

    out = tmp_path / "clip.mp4"
    render_preview([first_frames(demo, 60)], out)
    frames, seconds = imageio_ffmpeg.count_frames_and_secs(str(out))
    assert frames == 60 and seconds == pytest.approx(2.0, abs=0.05)
    reader = imageio_ffmpeg.read_frames(str(out))
    meta = next(reader)
    reader.close()
    assert tuple(meta["size"]) == (360, 360) and meta["fps"] == pytest.approx(30.0)


def test_three_clips_side_by_side(tmp_path, demo):
    pytest.importorskip("matplotlib")
    from PIL import Image

    from sinmdm.preview import CLIP_COLOURS
    from sinmdm.preview.render import render_preview

    clips = [first_frames(demo, 30), first_frames(demo, 45, start=100), first_frames(demo, 20, start=200)]
    info = render_preview(clips, tmp_path / "three.gif", labels=["input", "output 1", "output 2"])
    assert info.frames == 45 and info.size == (1080, 360)  # the longest clip; the others hold their last pose
    with Image.open(tmp_path / "three.gif") as gif:
        assert gif.n_frames == 45
        gif.seek(40)
        rgb = np.asarray(gif.convert("RGB"))
    for k, colour in enumerate(CLIP_COLOURS[:3]):
        panel = colour_pixels(rgb[:, k * 360:(k + 1) * 360], colour)
        assert panel.sum() > 300, f"panel {k} shows no skeleton"
        others = colour_pixels(np.delete(rgb, np.s_[k * 360:(k + 1) * 360], axis=1), colour)
        assert others.sum() < panel.sum() / 20


def test_high_rate_clip_is_decimated_for_gif(tmp_path, demo):
    pytest.importorskip("matplotlib")
    from sinmdm.preview.render import render_preview

    info = render_preview([first_frames(demo, 60)], tmp_path / "fast.gif", fps=120.0)  # 0.5 s of motion
    assert info.fps == 40.0 and info.frames == 20  # 120 / 3: GIF delays under 20 ms are slowed by browsers


def test_render_refuses_unknown_format(tmp_path, demo):
    from sinmdm.preview.render import render_preview

    with pytest.raises(SinMDMError, match="use .gif or .mp4"):
        render_preview([demo], tmp_path / "clip.avi")
    assert not (tmp_path / "clip.avi").exists()


# --------------------------------------------------------------------------- HTML viewer


def run_chromium(tmp_path: Path, *args: str) -> subprocess.CompletedProcess:
    profile = tmp_path / f"chromium-profile-{len(list(tmp_path.iterdir()))}"
    return subprocess.run(
        [str(CHROMIUM), *CHROMIUM_FLAGS, f"--user-data-dir={profile}", *args],
        capture_output=True, text=True, timeout=60,
    )


def test_viewer_is_self_contained(tmp_path, demo):
    from sinmdm.preview.viewer import write_viewer

    out = write_viewer([first_frames(demo, 30)], tmp_path / "view.html", labels=["</script><b>x"])
    text = out.read_text()
    assert "http://" not in text and "https://" not in text and "<script src" not in text
    assert text.count("</script>") == 2  # the label cannot close the data element early
    data = text.split('type="application/json">', 1)[1].split("</script>", 1)[0]
    payload = json.loads(data)
    assert payload["clips"][0]["label"] == "</script><b>x"
    assert len(payload["clips"][0]["points"]) == 30 * (19 + 5) * 3  # joints and End Sites per frame


@pytest.mark.skipif(not CHROMIUM.exists(), reason="needs Debian's chromium (apt-get install -y chromium)")
def test_viewer_plays_in_headless_chromium(tmp_path, demo):
    from PIL import Image

    from sinmdm.preview import CLIP_COLOURS
    from sinmdm.preview.viewer import write_viewer

    page = write_viewer([demo, first_frames(demo, 200, start=100)], tmp_path / "view.html")
    url = page.resolve().as_uri()
    shot = tmp_path / "shot.png"
    result = run_chromium(tmp_path, "--window-size=900,500", "--virtual-time-budget=1500", f"--screenshot={shot}", url)
    assert shot.exists(), result.stderr[-2000:]
    rgb = np.asarray(Image.open(shot).convert("RGB"))
    assert rgb.shape == (500, 900, 3)
    half = rgb.shape[1] // 2
    for colour, side in ((CLIP_COLOURS[0], np.s_[:, :half]), (CLIP_COLOURS[1], np.s_[:, half:])):
        assert colour_pixels(rgb[side], colour).sum() > 80, f"no {colour} skeleton in the screenshot"

    dom = run_chromium(tmp_path, "--window-size=900,500", "--virtual-time-budget=1500", "--dump-dom", url).stdout
    body = dom[dom.index("<body"):dom.index(">", dom.index("<body"))]
    attributes = dict(part.split("=") for part in body.replace('"', "").split()[1:])
    assert int(attributes["data-drawn"]) > 5 and int(attributes["data-frame"]) > 0, body


# --------------------------------------------------------------------------- glTF


def check_glb_structure(path: Path, bvh: BVH) -> None:
    pygltflib = pytest.importorskip("pygltflib")
    gltf = pygltflib.GLTF2().load_binary(str(path))
    skeleton = bvh.skeleton
    names = [node.name for node in gltf.nodes]
    assert names[:skeleton.num_joints] == list(skeleton.names)
    assert len(gltf.skins) == 1 and len(gltf.skins[0].joints) == skeleton.num_joints + len(skeleton.end_sites)
    ibm = gltf.accessors[gltf.skins[0].inverseBindMatrices]
    assert (ibm.type, ibm.count) == ("MAT4", len(gltf.skins[0].joints))
    (animation,) = gltf.animations
    rotation = [c for c in animation.channels if c.target.path == "rotation"]
    translation = [c for c in animation.channels if c.target.path == "translation"]
    assert len(rotation) == skeleton.num_joints
    assert len(translation) == sum(1 for j in range(skeleton.num_joints) if skeleton.position_channels(j))
    times = gltf.accessors[animation.samplers[0].input]
    assert times.count == bvh.frames and times.max[0] == pytest.approx((bvh.frames - 1) * bvh.frame_time, rel=1e-3)
    assert all(s.interpolation == "LINEAR" for s in animation.samplers)
    mesh_nodes = [n for n in gltf.nodes if n.mesh is not None]
    assert len(mesh_nodes) == 1 and mesh_nodes[0].skin == 0


@pytest.mark.parametrize(
    "clip",
    [
        "demo",
        pytest.param("Crabnew_Crab-dance-long.bvh", marks=pytest.mark.realdata),
        pytest.param("Xia_normal.bvh", marks=pytest.mark.realdata),  # ZYX rotation order, 120 fps
    ],
)
def test_glb_round_trip(tmp_path, clip):
    pytest.importorskip("pygltflib")
    from sinmdm.preview.gltf import read_glb, write_glb

    bvh = read_bvh(DEMO_CLIP if clip == "demo" else real_clip(clip))
    path = write_glb(bvh, tmp_path / "clip.glb")
    check_glb_structure(path, bvh)
    back = read_glb(path)
    assert back["names"] == list(bvh.skeleton.names)
    assert np.array_equal(back["parents"], bvh.skeleton.parents)
    assert back["frames"] == bvh.frames
    assert back["fps"] == pytest.approx(1.0 / bvh.frame_time, rel=1e-3)
    assert np.allclose(np.linalg.norm(back["rotations"], axis=-1), 1.0)
    expected = global_positions(animation_from_bvh(bvh)) * unit_scale(bvh.skeleton)
    assert np.abs(back["positions"] - expected).max() < 1e-4


def test_glb_of_several_roots_and_bare_end_sites(tmp_path):
    pytest.importorskip("pygltflib")
    from sinmdm.preview.gltf import read_glb, write_glb
    from sinmdm.runtime.bvh import parse_bvh

    text = (
        "HIERARCHY\nROOT A\n{\nOFFSET 0 0 0\nCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
        "JOINT A_end\n{\nOFFSET 0 0.5 0\nCHANNELS 0\nEnd Site\n{\n}\n}\n}\n"
        "ROOT B\n{\nOFFSET 1 0 0\nCHANNELS 3 Yposition Xrotation Zrotation\nEnd Site\n{\nOFFSET 0 0.3 0\n}\n}\n"
        "MOTION\nFrames: 2\nFrame Time: 0.04\n0 1 0 10 20 30 0.5 45 10\n0 1 0 15 25 35 0.6 40 5\n"
    )
    bvh = parse_bvh(text)
    back = read_glb(write_glb(bvh, tmp_path / "roots.glb"))
    assert back["names"] == ["A", "A_end", "B"] and back["parents"].tolist() == [-1, 0, -1]
    assert back["fps"] == pytest.approx(25.0) and back["frames"] == 2
    assert [p for p, _ in back["end_sites"]] == [1, 2]
    expected = global_positions(animation_from_bvh(bvh)) * unit_scale(bvh.skeleton)
    assert np.abs(back["positions"] - expected).max() < 1e-6


def test_read_glb_rejects_other_files(tmp_path):
    pytest.importorskip("pygltflib")
    from sinmdm.preview.gltf import read_glb

    bad = tmp_path / "bad.glb"
    bad.write_bytes(b"not a glb at all")
    with pytest.raises(SinMDMError, match="not a GLB"):
        read_glb(bad)


@pytest.mark.skipif(not os.environ.get("SINMDM_GLTF_VALIDATOR"),
                    reason="set SINMDM_GLTF_VALIDATOR to a folder where `npm install gltf-validator` ran")
def test_glb_passes_khronos_validator(tmp_path, demo):
    from sinmdm.preview.gltf import write_glb

    path = write_glb(demo, tmp_path / "demo.glb")
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


# --------------------------------------------------------------------------- CLI and the optional extra


def test_gif_of_a_large_crowd(tmp_path, demo):
    """16 clips (more than the palette held one ramp each for, issue 15): the GIF is written."""
    pytest.importorskip("matplotlib")
    from PIL import Image

    from sinmdm.preview.render import render_preview

    clips = [first_frames(demo, 4, start=10 * k) for k in range(16)]
    render_preview(clips, tmp_path / "crowd.gif")
    with Image.open(tmp_path / "crowd.gif") as gif:
        assert gif.n_frames == 4


def test_streamed_gif_holds_every_frame_and_delay(tmp_path):
    """write_gif streams (one frame held, not all): the file decodes to the frames given, a repeated
    frame folded into the previous delay, and only changed rectangles stored."""
    pytest.importorskip("PIL")
    from PIL import Image, ImageSequence

    from sinmdm.preview.render import BACKGROUND, write_gif

    inks = ["#e4572e", "#2e86de"]
    canvas = np.full((40, 60, 4), 255, np.uint8)
    canvas[..., :3] = (np.array([int(BACKGROUND[k:k + 2], 16) for k in (1, 3, 5)]))
    frames = []
    for k in range(5):
        frame = canvas.copy()
        frame[10:20, 5 + 10 * min(k, 3):15 + 10 * min(k, 3), :3] = (0xe4, 0x57, 0x2e)  # frames 3 and 4 equal
        frames.append(frame)
    out = tmp_path / "streamed.gif"
    write_gif(out, iter(frames), [30, 40, 30, 30, 40], inks)
    with Image.open(out) as gif:
        decoded = [(np.asarray(f.convert("RGB")), f.info["duration"], f.dispose_extent)
                   for f in ImageSequence.Iterator(gif)]
    assert [d for _, d, _ in decoded] == [30, 40, 30, 70]
    assert [extent for _, _, extent in decoded] == [(0, 0, 60, 40), (5, 10, 25, 20), (15, 10, 35, 20), (25, 10, 45, 20)]
    for (pixels, _, _), frame in zip(decoded, frames):
        assert np.array_equal(pixels, frame[..., :3])


def test_cli_preview_writes_and_refuses_to_overwrite(tmp_path):
    pytest.importorskip("matplotlib")
    out = tmp_path / "x.gif"
    run_cli("sinmdm-run", "preview", str(DEMO_CLIP), "--out", str(out), "--max-seconds", "1", "--html", check=True)
    assert out.stat().st_size > 0 and out.with_suffix(".html").exists()
    before = out.stat().st_mtime_ns

    refused = run_cli("sinmdm-run", "preview", str(DEMO_CLIP), "--out", str(out))
    assert refused.returncode == 2
    assert refused.stderr.strip().count("\n") == 0 and "--force" in refused.stderr
    assert out.stat().st_mtime_ns == before

    forced = run_cli("sinmdm-run", "preview", str(DEMO_CLIP), "--out", str(out), "--max-seconds", "0.5", "--force", "--json")
    assert forced.returncode == 0, forced.stderr
    assert json.loads(forced.stdout)["frames"] == 15


def test_cli_preview_rejects_unknown_extension(tmp_path):
    result = run_cli("sinmdm-run", "preview", str(DEMO_CLIP), "--out", str(tmp_path / "x.avi"))
    assert result.returncode == 2 and result.stderr.strip().count("\n") == 0
    assert "use .gif, .mp4 or .html" in result.stderr
    assert list(tmp_path.iterdir()) == []


def test_cli_preview_without_the_extra_explains_how_to_get_it(tmp_path):
    blocker = tmp_path / "block"
    (blocker / "matplotlib").mkdir(parents=True)
    (blocker / "matplotlib" / "__init__.py").write_text("raise ImportError('blocked in this test')\n")
    result = run_cli("sinmdm-run", "preview", str(DEMO_CLIP), "--out", str(tmp_path / "x.gif"), env={"PYTHONPATH": str(blocker)})
    assert result.returncode == 2
    assert result.stderr.strip() == "error: previews need the preview extra: pip install 'sinmdm[preview]'"
    assert not (tmp_path / "x.gif").exists()


def test_runtime_and_cli_do_not_import_preview_libraries():
    code = (
        "import sys, sinmdm.cli.run, sinmdm.runtime.bvh, sinmdm.runtime.animation, sinmdm.runtime.features\n"
        "heavy = ('matplotlib', 'imageio', 'imageio_ffmpeg', 'pygltflib', 'PIL', 'sinmdm.preview')\n"
        "loaded = [m for m in heavy if m in sys.modules]\n"
        "assert not loaded, loaded\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60)
