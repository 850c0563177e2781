"""One writer for every output (issue 15, parts 3 and 5): real files, real processes, real OS faults."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from sinmdm.runtime import SamplingOptions, generate, load_model, read_bvh
from sinmdm.runtime.atomic import OutputSet, atomic_path, check_writable_dir, write_text_atomic
from sinmdm.runtime.errors import OptionError, SinMDMError
from sinmdm.runtime.outputs import plan_sample_outputs, write_outputs

from .conftest import DEMO_CLIP, call_cli, run_cli

SAMPLE = Path(sys.executable).parent / "sinmdm-run"


def temps(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir() if ".part" in p.name)


def dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def demo_sampling(count: int = 2, frames: int = 30):
    """The bundled demo model and a real generation (2 denoising steps: fast)."""
    model = load_model()
    return model, generate(model, frames, SamplingOptions(count=count, steps=2))


def limited_fsize(limit: int):
    """A child that may not write files over `limit` bytes: writes then fail with EFBIG (Python ignores SIGXFSZ)."""
    import resource

    return lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))


# --------------------------------------------------------------------------- checks before any work


@pytest.mark.parametrize("name", ["../x", "/tmp/x", "a/b", "", ".", "..", "x" * 240])
def test_names_outside_the_directory_are_refused(tmp_path, name):
    with pytest.raises(OptionError) as refused:
        OutputSet(tmp_path / "out", [name])
    assert refused.value.option == "name"
    with pytest.raises(OptionError) as refused:
        plan_sample_outputs(tmp_path / "out", name, [0])
    assert refused.value.option == "name"
    assert not (tmp_path / "x").exists() and not (tmp_path / "x_0000.bvh").exists()


def test_cli_name_outside_out_is_refused(tmp_path):
    for name in ("../x", str(tmp_path / "abs")):
        result = run_cli("sinmdm-run", "sample", "--seconds", "1", "--steps", "2", "--out", str(tmp_path / "out"),
                         "--name", name)
        assert result.returncode == 2, result.stderr
        assert result.stderr.strip().count("\n") == 0 and "--name" in result.stderr
    assert not list(tmp_path.rglob("*.bvh"))


def test_unwritable_directories_are_refused(tmp_path):
    regular = tmp_path / "somefile"
    regular.write_text("x")
    for directory in (regular / "sub", regular, Path("/proc/self")):
        with pytest.raises(OptionError) as refused:
            OutputSet(directory, ["a.bvh"])
        assert refused.value.option == "out" and str(directory) in str(refused.value)
    with pytest.raises(OptionError):
        check_writable_dir(regular / "sub")


def test_existing_targets_need_force_and_never_a_directory(tmp_path):
    (tmp_path / "a.bvh").write_text("old")
    with pytest.raises(SinMDMError, match="--force"):
        OutputSet(tmp_path, ["a.bvh"])
    (tmp_path / "d.bvh").mkdir()
    os.mkfifo(tmp_path / "f.bvh")
    for name in ("d.bvh", "f.bvh"):
        with pytest.raises(SinMDMError, match="not a regular file"):
            OutputSet(tmp_path, [name], force=True)
    with pytest.raises(SinMDMError, match="not enough space"):
        OutputSet(tmp_path, ["new.bvh"], estimate_bytes=2**62)
    assert (tmp_path / "a.bvh").read_text() == "old"


def test_cli_refuses_before_sampling(tmp_path):
    """Existing outputs, an unwritable --out: refused at once, not after hours of sampling."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "sample_0000.bvh").write_text("old")
    regular = tmp_path / "somefile"
    regular.write_text("x")
    long_job = ["--count", "200", "--seconds", "600", "--steps", "50"]
    for target, expected in ((out, "--force"), (regular / "sub", "--out")):
        result = subprocess.run([str(SAMPLE), "sample", *long_job, "--out", str(target)], capture_output=True,
                                text=True, timeout=30)  # sampling all that would take hours
        assert result.returncode == 2 and expected in result.stderr, result.stderr
        assert result.stderr.strip().count("\n") == 0
    assert (out / "sample_0000.bvh").read_text() == "old"


def test_cli_refuses_a_directory_as_target_even_with_force(tmp_path):
    (tmp_path / "convert.bvh").mkdir()
    result = run_cli("sinmdm-run", "convert", str(DEMO_CLIP), str(tmp_path / "convert.bvh"), "--force")
    assert result.returncode == 2 and "not a regular file" in result.stderr, result.stderr
    assert (tmp_path / "convert.bvh").is_dir() and not temps(tmp_path)


# --------------------------------------------------------------------------- writing


def test_all_files_appear_together_and_are_fsynced(tmp_path, monkeypatch):
    synced = []
    real_fsync = os.fsync

    def recording_fsync(fd):  # a spy: the real fsync still runs
        synced.append(os.readlink(f"/proc/self/fd/{fd}"))
        real_fsync(fd)

    monkeypatch.setattr(os, "fsync", recording_fsync)
    with OutputSet(tmp_path, ["a.bvh", "b.npz"]) as out:
        out.write_text("a.bvh", "A")
        assert not (tmp_path / "a.bvh").exists()
        out.write("b.npz", lambda tmp: np.savez(tmp, x=np.arange(3)))  # a writer that picks the format by suffix
        assert len(temps(tmp_path)) == 2
        paths = out.commit()
    assert [p.name for p in paths] == ["a.bvh", "b.npz"] and not temps(tmp_path)
    assert (tmp_path / "a.bvh").read_text() == "A" and np.load(tmp_path / "b.npz")["x"].tolist() == [0, 1, 2]
    assert any(".a.bvh." in s for s in synced) and any(".b.npz." in s for s in synced)
    assert str(tmp_path) in synced  # the directory, after the renames


def test_a_failure_or_interrupt_removes_every_temp(tmp_path):
    for failure in (RuntimeError("boom"), KeyboardInterrupt(), SystemExit(143)):
        def broken(tmp, failure=failure):
            tmp.write_text("half")
            raise failure

        with pytest.raises(type(failure)):
            with OutputSet(tmp_path, ["a.bvh", "b.bvh"], force=True) as out:
                out.write_text("a.bvh", "A")
                out.write("b.bvh", broken)
        assert os.listdir(tmp_path) == []


def test_leaving_without_commit_writes_nothing(tmp_path):
    with OutputSet(tmp_path, ["a.bvh"]) as out:
        out.write_text("a.bvh", "A")
    assert os.listdir(tmp_path) == []


def test_temps_are_exclusive_and_unguessable(tmp_path):
    names = set()
    for _ in range(3):
        with OutputSet(tmp_path, ["a.bvh"], force=True) as out:
            out.write("a.bvh", lambda tmp: names.add(tmp.name))
            out.commit()
    assert len(names) == 3 and all(n.startswith(f".a.bvh.{os.getpid()}.") and n.endswith(".part.bvh") for n in names)


def test_planted_links_are_never_written_through(tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    out = tmp_path / "out"
    out.mkdir()
    (out / ".sample_0000.part.bvh").symlink_to(victim)  # the old fixed temp name
    (out / "sample_0000.bvh").symlink_to(victim)
    result = run_cli("sinmdm-run", "sample", "--seconds", "1", "--steps", "2", "--out", str(out), "--force")
    assert result.returncode == 0, result.stderr
    assert victim.read_text() == "precious"
    assert (out / "sample_0000.bvh").is_file() and not (out / "sample_0000.bvh").is_symlink()
    assert read_bvh(out / "sample_0000.bvh").frames == 30


def test_stale_temps_of_dead_writers_are_cleaned(tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    out = tmp_path / "out"
    out.mkdir()
    dead, alive = dead_pid(), os.getpid()
    stale = out / f".sample_0000.bvh.{dead}.0123456789ab.part.bvh"
    stale.write_text("half")
    stale_link = out / f".x.pt.{dead}.0123456789ab.part.pt"
    stale_link.symlink_to(victim)
    live = out / f".sample_0001.bvh.{alive}.0123456789ab.part.bvh"
    live.write_text("being written")
    OutputSet(out, ["other.bvh"]).close()
    assert not stale.exists() and not stale_link.is_symlink() and live.exists()
    assert victim.read_text() == "precious"


def test_single_file_helpers_keep_working(tmp_path):
    target = tmp_path / "sub" / "file.txt"
    write_text_atomic(target, "one")
    write_text_atomic(target, "two")  # overwrite, as before
    with atomic_path(target) as tmp:
        tmp.write_text("three")
    assert target.read_text() == "three" and os.listdir(target.parent) == ["file.txt"]
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("boom")
    assert target.read_text() == "three" and os.listdir(target.parent) == ["file.txt"]


# --------------------------------------------------------------------------- real OS faults


def test_disk_full_is_one_error_and_leaves_nothing(tmp_path):
    script = ("from sinmdm.runtime.atomic import OutputSet\n"
              "from sinmdm.runtime.errors import SinMDMError\n"
              f"out = OutputSet({str(tmp_path)!r}, ['small.bvh', 'big.bvh'])\n"
              "out.write_bytes('small.bvh', b'x' * 100)\n"
              "try:\n"
              "    out.write_bytes('big.bvh', b'x' * 100_000)\n"
              "except SinMDMError as exc:\n"
              "    print(exc)\n")
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                            preexec_fn=limited_fsize(10_000), timeout=60)
    assert result.returncode == 0, result.stderr
    assert "big.bvh" in result.stdout and "too large" in result.stdout.lower()
    assert os.listdir(tmp_path) == []


def test_cli_sample_on_a_full_disk(tmp_path):
    out = tmp_path / "out"
    result = subprocess.run([str(SAMPLE), "sample", "--count", "3", "--seconds", "10", "--steps", "2",
                             "--out", str(out)], capture_output=True, text=True, preexec_fn=limited_fsize(50_000),
                            timeout=120)
    assert result.returncode == 2, result.stderr
    assert result.stderr.strip().startswith("error: cannot write") and result.stderr.strip().count("\n") == 0
    assert "sample_0000.bvh" in result.stderr
    assert os.listdir(out) == []


def test_cli_convert_on_a_full_disk(tmp_path):
    target = tmp_path / "out" / "clip.bvh"
    result = subprocess.run([str(SAMPLE), "convert", str(DEMO_CLIP), str(target)], capture_output=True, text=True,
                            preexec_fn=limited_fsize(10_000), timeout=120)
    assert result.returncode == 2, result.stderr
    assert result.stderr.startswith("error: cannot write") and result.stderr.count("\n") == 1, result.stderr
    assert "clip.bvh" in result.stderr and os.listdir(target.parent) == []


def _sample_until_a_temp_exists(out: Path, *args: str) -> subprocess.Popen:
    """Start `sinmdm-run sample` and return once one of its temp files exists in `out`."""
    process = subprocess.Popen([str(SAMPLE), "sample", "--out", str(out), "--steps", "2", *args],
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and process.poll() is None:
        if out.is_dir() and any(n.endswith(".part.bvh") for n in os.listdir(out)):
            return process
    process.kill()
    raise AssertionError(f"no temp file appeared: {process.communicate()[1]}")


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_interrupt_while_writing_leaves_no_temp_and_no_partial_set(tmp_path, signum):
    out = tmp_path / "out"
    process = _sample_until_a_temp_exists(out, "--count", "12", "--seconds", "30")
    process.send_signal(signum)
    _, stderr = process.communicate(timeout=60)
    assert "Traceback" not in stderr
    left = sorted(os.listdir(out))
    assert left == [] or left == [f"sample_{k:04d}.bvh" for k in range(12)], left
    assert process.returncode != 0 or len(left) == 12


def test_sigkill_during_force_overwrite_never_mixes(tmp_path):
    out = tmp_path / "out"
    run_cli("sinmdm-run", "sample", "--count", "4", "--seconds", "1", "--steps", "2", "--out", str(out), check=True)
    old = {p.name: p.read_bytes() for p in out.iterdir()}
    process = _sample_until_a_temp_exists(out, "--count", "4", "--seconds", "60", "--force")
    process.kill()
    process.communicate(timeout=60)
    now = {p.name: p.read_bytes() for p in out.iterdir() if not p.name.startswith(".")}
    assert now == old or all(now[n] != old[n] for n in old)  # all old or all new, never a mix
    stale = temps(out)
    assert all(f".{process.pid}." in name for name in stale)

    run_cli("sinmdm-run", "sample", "--count", "4", "--seconds", "2", "--steps", "2", "--out", str(out), "--force",
            check=True)
    assert temps(out) == []  # the dead run's temps are cleaned
    assert all(read_bvh(out / name).frames == 60 for name in old)


# --------------------------------------------------------------------------- sampling outputs and previews


def test_write_outputs_keeps_working_for_api_callers(tmp_path):
    model, result = demo_sampling()
    paths = write_outputs(model, result, tmp_path / "api", npz=True)
    assert [p.name for p in paths] == ["sample_0000.bvh", "sample_0000.npz", "sample_0001.bvh", "sample_0001.npz"]
    assert temps(tmp_path / "api") == []
    with pytest.raises(SinMDMError, match="preview extra"):
        write_outputs(model, result, tmp_path / "api2", preview=True)
    with pytest.raises(SinMDMError, match="preview extra"):
        plan_sample_outputs(tmp_path / "api2", "sample", [0], fmt="glb")
    with pytest.raises(OptionError, match="unknown format"):
        plan_sample_outputs(tmp_path / "api2", "sample", [0], fmt="fbx")


def test_a_preview_failure_keeps_the_samples(tmp_path):
    pytest.importorskip("matplotlib")
    from sinmdm.cli.writers import extra_writers

    model, result = demo_sampling(frames=10)
    out = tmp_path / "out"
    planned = plan_sample_outputs(out, "sample", [0, 1], preview=True, writers=extra_writers("bvh", True))
    (out / "sample_preview.gif").mkdir()  # appears while sampling: the preview cannot be renamed into place
    with pytest.raises(SinMDMError, match="samples? file.* were written"):
        planned.write(model, result)
    assert read_bvh(out / "sample_0000.bvh").frames == 10 and read_bvh(out / "sample_0001.bvh").frames == 10
    assert temps(out) == []


def test_cli_preview_failure_keeps_the_samples(tmp_path):
    """A real failure after sampling: the BVHs fit under the file-size limit, the GIF does not."""
    pytest.importorskip("matplotlib")
    out = tmp_path / "out"
    result = subprocess.run([str(SAMPLE), "sample", "--count", "2", "--seconds", "2", "--steps", "2", "--preview",
                             "--out", str(out)], capture_output=True, text=True, preexec_fn=limited_fsize(60_000),
                            timeout=120)
    assert result.returncode == 2, result.stderr
    assert result.stderr.strip().count("\n") == 0 and "sample_preview.gif" in result.stderr, result.stderr
    assert read_bvh(out / "sample_0000.bvh").frames == 60 and read_bvh(out / "sample_0001.bvh").frames == 60
    assert sorted(os.listdir(out)) == ["sample_0000.bvh", "sample_0001.bvh"]


def test_cli_sample_glb_and_preview(tmp_path):
    pytest.importorskip("matplotlib")
    out = tmp_path / "out"
    result = run_cli("sinmdm-run", "sample", "--count", "2", "--seconds", "1", "--steps", "2", "--format", "glb",
                     "--preview", "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert sorted(os.listdir(out)) == ["sample_0000.glb", "sample_0001.glb", "sample_preview.gif"]


def test_cli_preview_of_16_clips_and_its_faults(tmp_path):
    pytest.importorskip("matplotlib")
    out = tmp_path / "crowd.gif"
    clips = [str(DEMO_CLIP)] * 16
    result = run_cli("sinmdm-run", "preview", *clips, "--out", str(out), "--max-seconds", "0.2", "--size", "320x320")
    assert result.returncode == 0, result.stderr
    from PIL import Image

    with Image.open(out) as gif:
        assert gif.n_frames == 6 and gif.size == (320, 320)

    (tmp_path / "dir.gif").mkdir()
    refused = run_cli("sinmdm-run", "preview", str(DEMO_CLIP), "--out", str(tmp_path / "dir.gif"), "--force")
    assert refused.returncode == 2 and "not a regular file" in refused.stderr

    full = subprocess.run([str(SAMPLE), "preview", *clips, "--out", str(tmp_path / "full.gif"), "--max-seconds", "1"],
                          capture_output=True, text=True, preexec_fn=limited_fsize(20_000), timeout=120)
    assert full.returncode == 2 and full.stderr.strip().startswith("error: cannot write"), full.stderr
    assert sorted(os.listdir(tmp_path)) == ["crowd.gif", "dir.gif"]


def test_runtime_outputs_do_not_load_the_preview_package():
    script = ("import sys, sinmdm.runtime.outputs, sinmdm.runtime.atomic\n"
              "print([m for m in sys.modules if m.startswith(('sinmdm.preview', 'sinmdm.cli', 'torch'))])\n")
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]"


def test_a_missing_preview_extra_is_reported_before_sampling(tmp_path):
    blocker = tmp_path / "block_preview"
    for package in ("matplotlib", "PIL"):
        (blocker / package).mkdir(parents=True)
        (blocker / package / "__init__.py").write_text(f"raise ImportError('{package} is blocked in this test')\n")
    out = tmp_path / "out"
    # a crowd that would sample for minutes: the refusal must come first
    result = run_cli("sinmdm-run", "sample", "--count", "200", "--frames", "3000", "--preview", "--out", str(out),
                     env={"PYTHONPATH": str(blocker)})
    assert result.returncode == 2 and result.stderr.count("\n") == 1, result.stderr
    assert "--preview needs the preview extra" in result.stderr
    assert not out.exists() or not any(out.iterdir())


def test_a_crowd_larger_than_the_free_space_is_refused_before_sampling(tmp_path):
    free = os.statvfs(tmp_path).f_bavail * os.statvfs(tmp_path).f_frsize
    frames = 100_000  # 55 minutes at the demo's 30 fps: under the length cap
    count = min(10_000, free // (frames * 12 * 10) + 1)  # at least 10 channels of 12 bytes each
    result = call_cli("sinmdm-run", "sample", "--count", str(count), "--frames", str(frames),
                      "--out", str(tmp_path / "out"))
    assert result.returncode == 2 and "not enough space" in result.stderr, result.stderr
    assert not any((tmp_path / "out").iterdir())
