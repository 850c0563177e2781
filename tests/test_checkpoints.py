"""Checkpoints that cannot lie: digests verified on resume and export, non-finite weights and
losses refused, --resume only on a run with steps left, damaged run files as one-line errors."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import zipfile
from pathlib import Path

import pytest
import torch

from sinmdm.runtime.atomic import temp_name
from sinmdm.train.checkpoint import CHECKPOINT, CONFIG, LOG

from .conftest import DEMO_CLIP, TINY_TRAIN_ARGS, call_cli


def resume(run_dir: Path, *args: str) -> subprocess.CompletedProcess:
    return call_cli("sinmdm", "train", str(DEMO_CLIP), "--out", str(run_dir), "--resume", *args, *TINY_TRAIN_ARGS)


def export(run_dir: Path, out: Path, *args: str) -> subprocess.CompletedProcess:
    return call_cli("sinmdm", "export", str(run_dir), "--out", str(out), *args)


def assert_one_line_error(result: subprocess.CompletedProcess, *words: str, alone: bool = True) -> None:
    """Exit 2 and one `error:` line naming `words`; `alone`: nothing else was printed (the
    error was found before any work)."""
    assert result.returncode == 2, result.stderr
    lines = result.stderr.splitlines()
    assert lines[-1].startswith("error: ") and [line for line in lines if "error" in line] == lines[-1:], result.stderr
    assert len(lines) == 1 or not alone, result.stderr
    assert "Traceback" not in result.stderr and all(w in lines[-1] for w in words), result.stderr


@pytest.fixture
def run(tiny_run, tmp_path) -> Path:
    """A copy of the tiny run (finished at step 10) to damage."""
    return Path(shutil.copytree(tiny_run, tmp_path / "run"))


def snapshot(run_dir: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(run_dir.iterdir()) if p.is_file()}


def largest_tensor_span(path: Path) -> tuple[int, int]:
    """(offset, size) of the largest tensor's bytes inside a torch zip checkpoint."""
    with zipfile.ZipFile(path) as archive:
        info = max((i for i in archive.infolist() if "/data/" in i.filename), key=lambda i: i.file_size)
    with open(path, "rb") as fh:
        fh.seek(info.header_offset + 26)
        name_length, extra_length = (int.from_bytes(fh.read(2), "little") for _ in range(2))
    return info.header_offset + 30 + name_length + extra_length, info.file_size


def flip_bytes(path: Path) -> None:
    data = bytearray(path.read_bytes())
    offset, size = largest_tensor_span(path)
    start = offset + size // 2
    data[start:start + 16] = bytes(b ^ 0xFF for b in data[start:start + 16])
    path.write_bytes(bytes(data))


def truncate(path: Path) -> None:
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def another_checkpoint(path: Path) -> None:
    """A valid checkpoint, but not the one the config names."""
    state = torch.load(path, weights_only=True)
    state["model"] = {k: v + 0.01 if v.is_floating_point() else v for k, v in state["model"].items()}
    torch.save(state, path)


def rewrite_with_checksum(run_dir: Path, change) -> None:
    """Damage the checkpoint's contents but record its new digest: a run that passes the checksum."""
    path = run_dir / CHECKPOINT
    state = torch.load(path, weights_only=True)
    change(state)
    torch.save(state, path)
    config = json.loads((run_dir / CONFIG).read_text())
    config["checksums"][CHECKPOINT] = hashlib.sha256(path.read_bytes()).hexdigest()
    (run_dir / CONFIG).write_text(json.dumps(config))


def test_config_records_the_checkpoint_digest(tiny_run):
    config = json.loads((tiny_run / CONFIG).read_text())
    assert config["checksums"][CHECKPOINT] == hashlib.sha256((tiny_run / CHECKPOINT).read_bytes()).hexdigest()


@pytest.mark.parametrize("damage", [flip_bytes, truncate, another_checkpoint])
def test_damaged_checkpoint_is_refused_by_resume_and_export(run, tmp_path, damage):
    damage(run / CHECKPOINT)
    before = snapshot(run)
    assert_one_line_error(resume(run, "--steps", "20"), str(run / CHECKPOINT), "corrupted")
    assert_one_line_error(export(run, tmp_path / "out" / "m.onnx"), str(run / CHECKPOINT), "corrupted")
    assert snapshot(run) == before and not (tmp_path / "out").exists()


def test_nan_weights_with_a_matching_checksum_are_refused(run, tmp_path):
    def poison(state):
        name = next(k for k, v in state["ema"].items() if v.is_floating_point() and v.numel() > 16)
        state["ema"][name].view(-1)[:16] = float("nan")

    rewrite_with_checksum(run, poison)
    before = snapshot(run)
    assert_one_line_error(resume(run, "--steps", "20"), "non-finite weights", str(run / CHECKPOINT))
    assert_one_line_error(export(run, tmp_path / "m.onnx"), "non-finite weights")
    assert snapshot(run) == before and list(tmp_path.glob("*.onnx")) == []


def test_non_finite_loss_stops_training_and_keeps_the_last_checkpoint(run):
    """NaN optimiser moments (weights still finite): the first step poisons the weights, the
    next loss is NaN; training stops with exit 2 and the step-10 checkpoint stays as it was."""
    def poison(state):
        for moments in state["optimizer"]["state"].values():
            moments["exp_avg"].fill_(float("nan"))

    rewrite_with_checksum(run, poison)
    before = snapshot(run)
    assert_one_line_error(resume(run, "--steps", "20"), "diverged", "non-finite", "step 10", alone=False)
    after = snapshot(run)
    assert after[CHECKPOINT] == before[CHECKPOINT] and after[CONFIG] == before[CONFIG]


def test_export_refuses_non_finite_outputs(run, tmp_path):
    """Finite weights whose outputs overflow: the parity check sees inf/NaN and writes nothing."""
    def overflow(state):
        for weights in (state["model"], state["ema"]):
            for value in weights.values():
                if value.is_floating_point():
                    value.fill_(3e38)

    rewrite_with_checksum(run, overflow)
    result = export(run, tmp_path / "m.onnx", "--checkpoint", "last")
    assert_one_line_error(result, "non-finite outputs", "nothing was written")
    assert list(tmp_path.glob("*.onnx")) == [] and not list(tmp_path.glob(".*part*"))


def test_resume_needs_a_run(tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    assert_one_line_error(resume(empty, "--steps", "2"), "--resume", "no run", str(empty))
    assert list(empty.iterdir()) == []
    assert_one_line_error(resume(tmp_path / "missing", "--steps", "2"), "no run")
    assert not (tmp_path / "missing").exists()


def test_resume_of_a_finished_run(run):
    before = snapshot(run)
    assert_one_line_error(resume(run), "finished at step 10", "--steps above 10")
    assert_one_line_error(resume(run, "--steps", "10"), "finished at step 10")
    assert_one_line_error(resume(run, "--steps", "5"), "finished at step 10")
    assert snapshot(run) == before
    result = resume(run, "--steps", "12")
    assert result.returncode == 0, result.stderr
    config = json.loads((run / CONFIG).read_text())
    assert config["step"] == 12 and config["steps"] == 12 and config["finished"]
    assert_one_line_error(resume(run), "finished at step 12")  # the run's own total, not the preset's


@pytest.mark.parametrize("damage, words", [
    (lambda c: {k: v for k, v in c.items() if k != "clip"}, ("'clip' is missing",)),
    (lambda c: [c], ("is not a run config",)),
    (lambda c: "text", ("is not a run config",)),
    (lambda c: None, ("is not a run config",)),
    (lambda c: {**c, "step": "10"}, ("'step' has the wrong type",)),
    (lambda c: {**c, "clip": {**c["clip"], "sha256": None}}, ("'clip.sha256'",)),
    (lambda c: {**c, "model": {**c["model"], "width": "32"}}, ("invalid model or training settings",)),
    (lambda c: {**c, "stage": {"dir": "../other", "norm": "frame", "steps": 1, "from_step": 1, "chosen": True}},
     ("stage.dir",)),
    (lambda c: {**c, "stages": [{"dir": "norm-frame/../../x", "norm": "frame", "steps": 1, "from_step": 1,
                                 "chosen": False}]}, ("stages[0].dir",)),
    (lambda c: {**c, "stages": ["norm-frame"]}, ("stages[0] is not a record",)),
])
def test_damaged_config_is_one_line_error(run, damage, words):
    (run / CONFIG).write_text(json.dumps(damage(json.loads((run / CONFIG).read_text()))))
    assert_one_line_error(call_cli("sinmdm", "info", str(run)), str(run / CONFIG), *words)


def test_config_without_clip_refused_by_resume_and_export(run, tmp_path):
    config = json.loads((run / CONFIG).read_text())
    del config["clip"]
    (run / CONFIG).write_text(json.dumps(config))
    assert_one_line_error(resume(run, "--steps", "12"), "'clip' is missing")
    assert_one_line_error(export(run, tmp_path / "m.onnx"), "'clip' is missing")


def test_damaged_log_records_are_skipped(run):
    log = run / LOG
    log.write_bytes(log.read_bytes() + b"\xff\xfe not utf-8\n[1, 2]\n{\"step\": 3, \"check\": [1]}\n\"text\"\n")
    assert call_cli("sinmdm", "info", str(run)).returncode == 0
    result = resume(run, "--steps", "12")
    assert result.returncode == 0, result.stderr
    assert [json.loads(line)["step"] for line in log.read_text().splitlines()] == [10, 3, 12]


def test_export_output_errors_come_before_the_work(run, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    assert_one_line_error(export(run, blocker / "m.onnx"), str(blocker))
    existing = tmp_path / "m_w48.onnx"
    existing.write_text("keep")
    assert_one_line_error(export(run, tmp_path / "m.onnx"), "--force")
    assert existing.read_text() == "keep"
    directory = tmp_path / "d_w48.onnx"
    directory.mkdir()
    assert_one_line_error(export(run, tmp_path / "d.onnx", "--force"), "not a regular file")


def dead_pid() -> int:
    process = subprocess.Popen(["true"])
    process.wait()
    return process.pid


def test_stale_checkpoint_temp_is_removed_by_the_next_save(run):
    """What a checkpoint write killed by SIGKILL leaves: a temp named for a dead writer."""
    stale = run / temp_name(CHECKPOINT).replace(f".{os.getpid()}.", f".{dead_pid()}.")
    stale.write_bytes(b"\0" * 4096)
    result = resume(run, "--steps", "11")
    assert result.returncode == 0, result.stderr
    assert not stale.exists() and not list(run.glob(".*.part*"))
