"""Training through torch.compile: chosen by the run's length, deterministic, and an eager
run when compiling fails."""

from __future__ import annotations

import json
from dataclasses import replace

import torch

from sinmdm.train.compiled import MIN_STEPS_TO_COMPILE, wants_compile
from sinmdm.train.presets import preset
from sinmdm.train.trainer import Run, load_clip

from .conftest import DEMO_CLIP, TINY_TRAIN_ARGS, call_cli, needs_compiler, run_cli

CPU = torch.device("cpu")


def tiny_run(compile_mode: str) -> Run:
    config = replace(preset("cpu"), width=32, batch=4, crop=48, check_every=None, steps=MIN_STEPS_TO_COMPILE)
    return Run(load_clip(DEMO_CLIP, config.fps, {}), config, seed=0, device=CPU, compile_mode=compile_mode)


def weights_after(run: Run, steps: int) -> tuple[list[float], dict]:
    losses = [run.train_step() for _ in range(steps)]
    return losses, {k: v.clone() for k, v in run.model.state_dict().items()}


def test_auto_compiles_only_runs_long_enough_to_pay():
    assert wants_compile("auto", MIN_STEPS_TO_COMPILE, CPU)[0]
    assert not wants_compile("auto", 150, CPU)[0]
    assert not wants_compile("auto", 2800, torch.device("mps"))[0]
    assert wants_compile("on", 10, CPU)[0] and not wants_compile("off", 2800, CPU)[0]


@needs_compiler
def test_compiled_training_is_deterministic_and_matches_eager():
    compiled = tiny_run("on")
    losses, weights = weights_after(compiled, 3)
    assert compiled.forward.compiled
    again_losses, again = weights_after(tiny_run("on"), 3)
    assert again_losses == losses and all(torch.equal(weights[k], again[k]) for k in weights)
    eager_losses, _ = weights_after(tiny_run("off"), 3)
    # the same batches and noise; only the kernels' rounding (and dropout's seeds) differ
    assert abs(eager_losses[0] - losses[0]) < 0.02 * eager_losses[0]


def test_failed_compilation_trains_eagerly(monkeypatch):
    class Broken(torch.nn.Module):
        def forward(self, *args):
            raise RuntimeError("no C++ compiler found")

    monkeypatch.setattr(torch, "compile", lambda model: Broken())
    fallback = tiny_run("on")
    losses, weights = weights_after(fallback, 3)
    assert not fallback.forward.compiled and "compilation failed" in fallback.forward.why
    assert "no C++ compiler" in fallback.forward.why
    eager_losses, eager = weights_after(tiny_run("off"), 3)
    assert losses == eager_losses and all(torch.equal(weights[k], eager[k]) for k in weights)


def test_run_config_says_whether_it_compiled(tmp_path):
    call_cli("sinmdm", "train", str(DEMO_CLIP), "--out", str(tmp_path / "run"), "--steps", "2", *TINY_TRAIN_ARGS, check=True)
    config = json.loads((tmp_path / "run" / "config.json").read_text())
    assert config["compiled"] == {"on": False, "why": f"auto: 2 steps, under the {MIN_STEPS_TO_COMPILE} where compiling pays"}
    info = run_cli("sinmdm", "info", str(tmp_path / "run"), check=True)
    shown = info.stdout + info.stderr
    assert "compiled" in shown and "no: auto: 2 steps" in shown
