"""Training: real short runs on the demo clip, durability, resume, bad input."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch
from dataclasses import replace

from sinmdm.runtime.bvh import BVH, read_bvh, write_bvh
from sinmdm.train.checkpoint import load_config, load_state
from sinmdm.train.data import BatchSampler, crop_starts
from sinmdm.train.presets import PRESETS, TrainConfig
from sinmdm.train.trainer import resolve_device

from .conftest import DEMO_CLIP, TINY_TRAIN_ARGS, needs_compiler, run_cli


def train(*args: str, check: bool = True):
    return run_cli("sinmdm", "train", *args, *TINY_TRAIN_ARGS, check=check)


def weights(run_dir: Path) -> dict[str, torch.Tensor]:
    state = load_state(run_dir)
    return {**{f"model.{k}": v for k, v in state["model"].items()}, **{f"ema.{k}": v for k, v in state["ema"].items()}}


def assert_same_weights(a: Path, b: Path) -> None:
    wa, wb = weights(a), weights(b)
    assert wa.keys() == wb.keys()
    for key in wa:
        assert torch.equal(wa[key], wb[key]), key


def test_short_run_and_info(tiny_run):
    info = json.loads(run_cli("sinmdm", "info", str(tiny_run), "--json", check=True).stdout)
    assert info["step"] == 10 and info["preset"] == "cpu" and info["finished"]
    assert info["clip"]["name"] == "stomper.bvh"
    assert info["window"] == 48 and info["receptive_field"] == 23
    assert info["crop"] == {"frames": 48, "why": "random crops of 48 frames"}
    assert info["parameters"] > 0
    log = [json.loads(line) for line in (tiny_run / "log.jsonl").read_text().splitlines()]
    assert [entry["step"] for entry in log] == [10]
    config = load_config(tiny_run)
    assert len(config["codec"]["layout"]) > 0 and config["schedule"]["name"] == "cosine"
    rich = run_cli("sinmdm", "info", str(tiny_run), check=True)
    assert "stomper.bvh" in rich.stdout + rich.stderr


def test_steps_is_the_total_to_reach(tmp_path):
    run_dir = tmp_path / "run"
    train(str(DEMO_CLIP), "--out", str(run_dir), "--steps", "5")
    first = weights(run_dir)
    train(str(DEMO_CLIP), "--out", str(run_dir), "--steps", "10", "--resume")
    config = load_config(run_dir)
    assert config["step"] == 10 and config["finished"]
    assert not all(torch.equal(first[k], v) for k, v in weights(run_dir).items())
    log = [json.loads(line)["step"] for line in (run_dir / "log.jsonl").read_text().splitlines()]
    assert log == [5, 10]


def test_frame_norm_option(tmp_path):
    run_dir = tmp_path / "frame"
    train(str(DEMO_CLIP), "--out", str(run_dir), "--steps", "2", "--norm", "frame")
    assert load_config(run_dir)["model"]["norm"] == "frame"
    bad = train(str(DEMO_CLIP), "--out", str(tmp_path / "bad"), "--steps", "2", "--norm", "batch", check=False)
    assert bad.returncode == 2 and "--norm must be group or frame" in bad.stderr
    assert not (tmp_path / "bad").exists()


def test_ema_and_loss_weighting_options(tmp_path):
    run_dir = tmp_path / "raw"
    train(str(DEMO_CLIP), "--out", str(run_dir), "--steps", "2", "--ema", "0", "--loss-weighting", "min-snr")
    config = load_config(run_dir)["train"]
    assert config["ema"] is None and config["loss_weighting"] == "min-snr"
    assert load_state(run_dir).get("ema") is None
    for flag, value, words in [("--ema", "1", "--ema must be"), ("--loss-weighting", "snr", "--loss-weighting must be")]:
        bad = train(str(DEMO_CLIP), "--out", str(tmp_path / "bad"), "--steps", "2", flag, value, check=False)
        assert bad.returncode == 2 and words in bad.stderr
        assert not (tmp_path / "bad").exists()


def test_min_snr_weighting_keeps_the_mean():
    from sinmdm.runtime.schedule import cosine_alphas_cumprod
    from sinmdm.train.diffusion import min_snr_weighting

    abar = cosine_alphas_cumprod()
    weights = min_snr_weighting(abar)(torch.arange(len(abar)))
    assert abs(float(weights.mean()) - 1.0) < 1e-5
    assert float(weights[0]) == float(weights.max()) and float(weights[-1]) < 1e-3  # capped when clean, ~0 at pure noise


@pytest.mark.parametrize("mode", [[], pytest.param(["--compile"], marks=needs_compiler)], ids=["eager", "compiled"])
def test_kill_and_resume(tmp_path, mode):
    run_dir = tmp_path / "killed"
    exe = Path(sys.executable).parent / "sinmdm"
    process = subprocess.Popen(
        [str(exe), "train", str(DEMO_CLIP), "--out", str(run_dir), "--steps", "150", *TINY_TRAIN_ARGS, *mode],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )
    deadline = time.time() + 180
    while time.time() < deadline:
        try:
            if load_config(run_dir)["step"] >= 10:
                break
        except Exception:
            pass
        time.sleep(0.05)
    process.send_signal(signal.SIGKILL)
    process.wait()
    config = load_config(run_dir)  # the pair on disk is consistent after a SIGKILL
    step = config["step"]
    assert 10 <= step < 150 and step % 5 == 0
    train(str(DEMO_CLIP), "--out", str(run_dir), "--steps", "150", "--resume", *mode)
    straight = tmp_path / "straight"
    train(str(DEMO_CLIP), "--out", str(straight), "--steps", "150", *mode)
    assert load_config(straight)["compiled"]["on"] == bool(mode)
    assert_same_weights(run_dir, straight)


def test_existing_run_needs_resume(tiny_run):
    result = train(str(DEMO_CLIP), "--out", str(tiny_run), "--steps", "20", check=False)
    assert result.returncode == 2 and "--resume" in result.stderr


def test_resume_from_another_clip_is_refused(tmp_path, tiny_run):
    other = tmp_path / "other.bvh"
    clip = read_bvh(DEMO_CLIP)
    write_bvh(other, BVH(clip.skeleton, clip.frame_time, clip.values[::-1].copy()))
    result = train(str(other), "--out", str(tiny_run), "--steps", "20", "--resume", check=False)
    assert result.returncode == 2 and "another file" in result.stderr
    assert load_config(tiny_run)["step"] == 10


def test_resume_with_other_config_is_refused(tiny_run):
    result = run_cli("sinmdm", "train", str(DEMO_CLIP), "--out", str(tiny_run), "--steps", "20", "--resume",
                     "--width", "64", "--batch", "4", "--crop", "48")
    assert result.returncode == 2 and "width" in result.stderr


def test_corrupted_checkpoint(tmp_path, tiny_run):
    import shutil

    broken = tmp_path / "broken"
    shutil.copytree(tiny_run, broken)
    (broken / "checkpoint.pt").write_bytes(b"not a checkpoint")
    result = train(str(DEMO_CLIP), "--out", str(broken), "--steps", "20", "--resume", check=False)
    assert result.returncode == 2 and "corrupted" in result.stderr and "Traceback" not in result.stderr


def test_clip_shorter_than_receptive_field(tmp_path):
    clip = read_bvh(DEMO_CLIP)
    short = tmp_path / "short.bvh"
    write_bvh(short, BVH(clip.skeleton, clip.frame_time, clip.values[:15].copy()))
    result = train(str(short), "--out", str(tmp_path / "run"), "--steps", "2", check=False)
    assert result.returncode == 2 and "receptive field" in result.stderr
    assert not (tmp_path / "run").exists()


def test_unwritable_output(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    result = train(str(DEMO_CLIP), "--out", str(blocker / "run"), "--steps", "2", check=False)
    assert result.returncode == 2 and "Traceback" not in result.stderr


def test_nan_clip_is_refused(tmp_path):
    text = DEMO_CLIP.read_text().splitlines()
    text[-1] = " ".join(["nan"] + text[-1].split()[1:])
    bad = tmp_path / "nan.bvh"
    bad.write_text("\n".join(text) + "\n")
    result = train(str(bad), "--out", str(tmp_path / "run"), "--steps", "2", check=False)
    assert result.returncode == 2 and "nan.bvh" in result.stderr


def test_paper_preset_batches_whole_clip_rescaled():
    config = PRESETS["paper"]
    assert (config.steps, config.batch, config.crop, config.lr, config.lr_gamma, config.ema) == (60000, 64, None, 1e-4, 0.99998, None)
    clip = torch.randn(10, 120)
    sampler = BatchSampler(clip, config, torch.Generator().manual_seed(0))
    lengths = {sampler().shape[2] for _ in range(20)}
    assert all(88 <= n <= 150 and n % 4 == 0 for n in lengths) and len(lengths) > 3
    batch = sampler()
    assert batch.shape[0] == 64 and torch.equal(batch[0], batch[63])


def test_cpu_preset_crops():
    config = PRESETS["cpu"]
    sampler = BatchSampler(torch.randn(10, 300), config, torch.Generator().manual_seed(0))
    batch = sampler()
    assert batch.shape == (64, 10, 64) and not torch.equal(batch[0], batch[1])


def test_crop_starts_reach_the_clip_ends():
    frames, length = 632, 64
    counts = {}
    for edges in (0.0, 0.25):
        starts = crop_starts(frames, length, edges, 200_000, torch.Generator().manual_seed(0))
        assert int(starts.min()) == 0 and int(starts.max()) == frames - length
        counts[edges] = torch.bincount(starts, minlength=frames - length + 1).double()
    # the crop at each end drawn 1 + 16 times as often as one in the middle; the middle stays uniform
    middle = counts[0.25][100:400].mean()
    assert abs(counts[0.25][0] / middle - 17) < 1.5 and abs(counts[0.25][-1] / middle - 17) < 1.5
    assert abs(counts[0.0][0] / counts[0.0][100:400].mean() - 1) < 0.2
    # an old run's config (no crop_edges) keeps uniform starts, so it resumes bit for bit
    old = {k: v for k, v in PRESETS["cpu"].to_dict().items() if k != "crop_edges"}
    assert TrainConfig.from_dict(old).crop_edges == 0.0 and PRESETS["cpu"].crop_edges == 0.0
    reaching = BatchSampler(torch.randn(10, 300), replace(PRESETS["cpu"], crop_edges=0.25), torch.Generator().manual_seed(0))
    assert reaching.crop_why == "random crops of 64 frames, starts up to 0.25 of a crop off the clip's ends"


def test_cpu_preset_trains_a_short_clip_whole():
    config = PRESETS["cpu"]
    short = torch.randn(10, 90)
    sampler = BatchSampler(short, config, torch.Generator().manual_seed(0))
    batch = sampler()
    assert sampler.window == 90 and batch.shape == (64, 10, 90) and all(torch.equal(b, short) for b in batch)
    assert "the whole clip" in sampler.crop_why
    longer = BatchSampler(torch.randn(10, 97), config, torch.Generator().manual_seed(0))
    assert longer.window == 64 and longer.crop_why.startswith("random crops of 64 frames")
    asked = BatchSampler(short, replace(config, crop=48, whole_clip_frames=None), torch.Generator().manual_seed(0))
    assert asked.window == 48


def test_short_clip_trains_whole_and_an_explicit_crop_wins(tmp_path):
    clip = read_bvh(DEMO_CLIP)
    short = tmp_path / "short.bvh"
    write_bvh(short, BVH(clip.skeleton, clip.frame_time, clip.values[:80].copy()))
    common = ("--steps", "2", "--width", "32", "--batch", "2", "--check-every", "0", "--no-compile")
    run_cli("sinmdm", "train", str(short), "--out", str(tmp_path / "whole"), *common, check=True)
    assert load_config(tmp_path / "whole")["window"] == 80
    shown = run_cli("sinmdm", "info", str(tmp_path / "whole"), check=True)
    shown = shown.stdout + shown.stderr
    assert "the whole clip" in shown
    run_cli("sinmdm", "train", str(short), "--out", str(tmp_path / "crops"), *common, "--crop", "64", check=True)
    assert load_config(tmp_path / "crops")["window"] == 64
    refused = run_cli("sinmdm", "train", str(short), "--out", str(tmp_path / "crops"), *common[2:], "--steps", "4",
                      "--resume", check=False)
    assert refused.returncode == 2 and "64 frames at a time" in refused.stderr


def test_paper_preset_runs_a_step(tmp_path):
    run_cli("sinmdm", "train", str(DEMO_CLIP), "--out", str(tmp_path / "paper"), "--preset", "paper",
            "--steps", "1", "--width", "32", "--batch", "2", check=True)
    config = load_config(tmp_path / "paper")
    assert config["train"]["preset"] == "paper" and config["window"] == 360


def test_device_auto_is_cpu_here():
    assert resolve_device("auto").type == ("cuda" if torch.cuda.is_available() else "cpu")


def test_the_foot_loss_is_off_where_a_clip_has_no_contacts_and_refused_when_asked(tmp_path):
    from sinmdm.runtime.errors import SinMDMError
    from sinmdm.train.trainer import train as run_training

    config = replace(PRESETS["cpu"], steps=1, width=32, batch=2, check_every=None, foot_loss=0.001, foot_loss_target="clip")
    result = run_training(DEMO_CLIP, tmp_path / "quiet", config, codec_options={"contacts": []}, compile_mode="off")
    assert result["foot_loss"] == {"on": False, "why": "off: the clip has no contact joints or no trajectory joint to hold"}
    with pytest.raises(SinMDMError, match="--foot-loss: the clip has no contact joints"):
        run_training(DEMO_CLIP, tmp_path / "asked", config, codec_options={"contacts": []}, compile_mode="off",
                     foot_loss_asked=True)
    assert not (tmp_path / "asked").exists()
