"""Shared fixtures: the project's own example clip, the real clips in ../shared/motions,
and a tiny trained model (trained once per test session, a few seconds)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DEMO_CLIP = ROOT / "sinmdm" / "runtime" / "demo" / "stomper.bvh"
SHARED_MOTIONS = ROOT.parent / "shared" / "motions"
REAL_CLIPS = sorted(SHARED_MOTIONS.glob("*.bvh")) if SHARED_MOTIONS.is_dir() else []
# Two real files declare a wrong frame time (1.0 s); they are 30 fps clips.
WRONG_FRAME_TIME = {"Joe_traj-example.bvh": 30.0, "Joe_Baseball-Milling-Idle-edited-keyframes.bvh": 30.0}


def real_clip(name: str) -> Path:
    path = SHARED_MOTIONS / name
    if not path.exists():
        pytest.skip(f"{path} not available")
    return path


def run_cli(*args: str, env: dict | None = None, check: bool = False, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """Run `sinmdm` or `sinmdm-run` (first arg) as a real process."""
    exe = Path(sys.executable).parent / args[0]
    merged = dict(os.environ, **(env or {}))
    result = subprocess.run([str(exe), *args[1:]], capture_output=True, text=True, env=merged, cwd=cwd, timeout=600)
    if check and result.returncode != 0:
        raise AssertionError(f"{args} failed ({result.returncode}):\n{result.stdout}\n{result.stderr}")
    return result


def call_cli(*args: str, check: bool = False) -> subprocess.CompletedProcess:
    """Run `sinmdm` or `sinmdm-run` (first arg) in this process: the console script's own
    entry point, without a new interpreter's start-up (about 2 s with torch). For what a
    process adds (signals, environment, a missing package) use run_cli."""
    import contextlib
    import io

    from sinmdm.cli import main as sinmdm_main, run as sinmdm_run

    entry = {"sinmdm": sinmdm_main.main, "sinmdm-run": sinmdm_run.main}[args[0]]
    stdout, stderr, argv = io.StringIO(), io.StringIO(), sys.argv
    sys.argv = list(args)
    code = 0
    try:
        with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
            entry()
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    finally:
        sys.argv = argv
    result = subprocess.CompletedProcess(list(args), code, stdout.getvalue(), stderr.getvalue())
    if check and code != 0:
        raise AssertionError(f"{args} failed ({code}):\n{result.stdout}\n{result.stderr}")
    return result


@pytest.fixture
def no_torch_env(tmp_path: Path) -> dict:
    """An environment in which `import torch` fails."""
    blocker = tmp_path / "block_torch"
    (blocker / "torch").mkdir(parents=True)
    (blocker / "torch" / "__init__.py").write_text("raise ImportError('torch is blocked in this test')\n")
    return {"PYTHONPATH": str(blocker)}


# inductor builds its CPU kernels with the system's C++ compiler
needs_compiler = pytest.mark.skipif(not (shutil.which("g++") or shutil.which("c++")),
                                    reason="no C++ compiler: torch.compile cannot build kernels here")

TINY_TRAIN_ARGS = ["--width", "32", "--batch", "4", "--crop", "48", "--checkpoint-every", "5", "--check-every", "0"]


@pytest.fixture(scope="session")
def tiny_run(tmp_path_factory) -> Path:
    """A real run on the demo clip: a width-32 denoiser trained for 10 steps."""
    run_dir = tmp_path_factory.mktemp("runs") / "tiny"
    run_cli("sinmdm", "train", str(DEMO_CLIP), "--out", str(run_dir), "--steps", "10", *TINY_TRAIN_ARGS, check=True)
    return run_dir


@pytest.fixture(scope="session")
def tiny_model(tiny_run, tmp_path_factory) -> Path:
    """The tiny run exported at its training window (48 frames)."""
    out = tmp_path_factory.mktemp("models") / "tiny.onnx"
    run_cli("sinmdm", "export", str(tiny_run), "--out", str(out), check=True)
    return out.with_name("tiny_w48.onnx")
