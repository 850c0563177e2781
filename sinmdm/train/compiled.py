"""The training forward pass through `torch.compile` when it pays off, eager otherwise.

Compiling costs about 45 s once per process (a C++ toolchain is needed on the CPU) and
saves about a third of every iteration of the `cpu` recipe (BENCHMARKS.md, "Training
speed"), so `auto` compiles only runs long enough to win it back, on devices whose
compiler backend is mature (CPU, CUDA). A run whose compilation fails trains eagerly,
and says why in its config."""

from __future__ import annotations

from dataclasses import dataclass

import torch

COMPILE_CHOICES = ("auto", "on", "off")
# iterations above which compiling pays: 46 s of compilation (empty cache) against 0.09-0.12 s
# saved per iteration at 2 threads is 370-530; the margin covers slower toolchains
MIN_STEPS_TO_COMPILE = 600


@dataclass(frozen=True)
class Forward:
    module: torch.nn.Module  # what the training step calls: the compiled graph or the model itself
    compiled: bool
    why: str  # one line for the run's config: the rule that decided, or the error that stopped it


def wants_compile(choice: str, steps: int, device: torch.device) -> tuple[bool, str]:
    if choice == "off":
        return False, "off (--no-compile)"
    if choice == "on":
        return True, "on (--compile)"
    if device.type not in ("cpu", "cuda"):
        return False, f"auto: not compiled on {device.type}"
    if steps < MIN_STEPS_TO_COMPILE:
        return False, f"auto: {steps} steps, under the {MIN_STEPS_TO_COMPILE} where compiling pays"
    return True, f"auto: {steps} steps"


def training_forward(model: torch.nn.Module, example: tuple[torch.Tensor, torch.Tensor], autocast: bool,
                     choice: str, steps: int) -> Forward:
    """`model` compiled, or `model` itself; `example` = (x_t, t) shaped like a real batch.
    The compiled graph is built here, forward and backward, so that a missing toolchain
    shows at the first step rather than in the middle of one; the trial's RNG draws are
    undone and its gradients dropped, so it changes nothing the run then draws (the batches
    are an eager run's; the dropout masks are the compiled kernels' own)."""
    device = example[0].device
    wanted, why = wants_compile(choice, steps, device)
    if not wanted:
        return Forward(model, False, why)
    rng = torch.get_rng_state()
    cuda_rng = torch.cuda.get_rng_state() if device.type == "cuda" else None
    compiled = torch.compile(model)
    model.train()
    try:
        with torch.autocast(device_type=device.type, dtype=torch.bfloat16, enabled=autocast):
            output = compiled(*example)
        output.float().square().mean().backward()
    except Exception as exc:  # noqa: BLE001 - any compiler failure means: train eagerly
        return Forward(model, False, f"{why}; compilation failed, trained eagerly ({type(exc).__name__}: "
                                     f"{str(exc).strip().splitlines()[0][:160] if str(exc).strip() else ''})")
    finally:
        torch.set_rng_state(rng)
        if cuda_rng is not None:
            torch.cuda.set_rng_state(cuda_rng)
        model.zero_grad(set_to_none=True)
    return Forward(compiled, True, why)
