"""Export a trained run's denoiser to ONNX: one static-window graph per window,
each file self-describing (skeleton, feature layout, schedule, provenance)."""

from __future__ import annotations

import contextlib
import hashlib
import io
import warnings
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import onnx
import torch

from .. import __version__
from ..runtime.atomic import OutputSet
from ..runtime.errors import SinMDMError
from ..runtime.model_format import INPUT_NAMES, METADATA_KEY, OUTPUT_NAME, encode_metadata, sidecar_path
from ..runtime.schedule import cosine_alphas_cumprod
from ..train.trainer import load_trained_model

DEFAULT_OPSET = 18
SUPPORTED_OPSETS = (17, 18)
MAX_IR_VERSION = 9
PARITY_TOLERANCE = 1e-4
PARITY_TIMESTEPS = (0, 1, 10, 250, 500, 999)
# Ops the graph may hold; anything else fails the export (no Einsum, norms, control flow, randomness).
ALLOWED_OPS = frozenset({
    "Add", "Sub", "Mul", "Div", "Neg", "Exp", "Sigmoid", "Sqrt", "Pow", "Reciprocal", "Cos", "Sin",
    "Conv", "Gemm", "MatMul", "Concat", "Reshape", "Unsqueeze", "Squeeze", "Transpose", "Slice", "Split",
    "ReduceMean", "ReduceMax", "ReduceSum", "ReduceL2", "Max", "Min", "Clip", "Shape", "Gather", "Expand", "Cast",
    "Constant", "ConstantOfShape", "Identity", "Tile", "Where", "Equal",
})


@dataclass
class ExportResult:
    path: Path
    window: int
    max_abs_diff: float
    opset: int
    ir_version: int
    ops: list[str]
    bytes: int


class _Graph(torch.nn.Module):
    """The exported signature: float32 x_t (B, F, W) and float32 t (B,) -> x0."""

    def __init__(self, model: torch.nn.Module):
        super().__init__()
        self.model = model

    def forward(self, x_t: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        return self.model(x_t, t)


def weights_id(model: torch.nn.Module) -> str:
    """Identifies the weights, so windows of different models are never mixed."""
    digest = hashlib.sha256()
    for name, tensor in sorted(model.state_dict().items()):
        digest.update(name.encode())
        digest.update(tensor.detach().to(torch.float32).contiguous().numpy().tobytes())
    return digest.hexdigest()[:16]


def window_path(out: Path, window: int) -> Path:
    stem = out.name[: -len(".onnx")] if out.name.endswith(".onnx") else out.name
    return out.with_name(f"{stem}_w{window}.onnx")


def _to_onnx(graph: torch.nn.Module, features: int, window: int, opset: int) -> onnx.ModelProto:
    """torch's dynamo exporter at opset 18 (batch dynamic, window fixed); opset 17 by
    onnx's version converter. (The legacy TorchScript exporter was tried first: its
    initializer de-duplication produced graphs with dangling inputs for some weights.)"""
    import logging

    from onnx import version_converter

    example = (torch.zeros(2, features, window), torch.zeros(2))
    batch = torch.export.Dim("batch", min=1, max=65536)
    previous = logging.getLogger("torch.onnx").level
    logging.getLogger("torch.onnx").setLevel(logging.ERROR)
    try:
        with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
            warnings.simplefilter("ignore")
            program = torch.onnx.export(
                graph, example, dynamo=True, opset_version=DEFAULT_OPSET, optimize=True, verbose=False,
                input_names=list(INPUT_NAMES), output_names=[OUTPUT_NAME],
                dynamic_shapes={INPUT_NAMES[0]: {0: batch}, INPUT_NAMES[1]: {0: batch}},
            )
    finally:
        logging.getLogger("torch.onnx").setLevel(previous)
    model = program.model_proto
    if opset != DEFAULT_OPSET:
        model = version_converter.convert_version(model, opset)
        _drop_attribute(model, "noop_with_empty_axes", keep_on=("ReduceSum",))
    model.ir_version = min(model.ir_version, MAX_IR_VERSION if opset >= 18 else 8)
    # The exporter annotates ~500 intermediate values with the symbolic `batch`; runtimes that
    # take them as facts (tract) then cannot run the graph at a fixed batch. Only inputs and
    # outputs keep their shapes; every runtime infers the rest.
    del model.graph.value_info[:]
    return model


def _drop_attribute(model: onnx.ModelProto, name: str, keep_on: tuple[str, ...]) -> None:
    """The 18 -> 17 converter leaves ReduceMean/ReduceMax with an attribute that only
    opset 18 (or ReduceSum) has; its default value is what opset 17 does anyway."""
    for node in model.graph.node:
        if node.op_type in keep_on:
            continue
        kept = [a for a in node.attribute if not (a.name == name and a.i == 0)]
        if len(kept) != len(node.attribute):
            del node.attribute[:]
            node.attribute.extend(kept)


def _check_graph(model: onnx.ModelProto) -> list[str]:
    onnx.checker.check_model(model, full_check=True)
    if len(model.graph.value_info):
        raise SinMDMError("export left intermediate shape annotations in the graph; this is a bug, please report it")
    ops = sorted({node.op_type for node in model.graph.node})
    forbidden = [op for op in ops if op not in ALLOWED_OPS]
    if forbidden:
        raise SinMDMError(f"export produced unsupported ops {forbidden}; this is a bug, please report it")
    for value in list(model.graph.input) + list(model.graph.output):
        if value.type.tensor_type.elem_type != onnx.TensorProto.FLOAT:
            raise SinMDMError(f"graph {value.name} is not float32")
    return ops


def _parity(model_bytes: bytes, graph: torch.nn.Module, features: int, window: int) -> float:
    import onnxruntime as ort

    session = ort.InferenceSession(model_bytes, providers=["CPUExecutionProvider"])
    generator = torch.Generator().manual_seed(0)
    worst = 0.0
    for t in PARITY_TIMESTEPS:
        x_t = torch.randn(2, features, window, generator=generator)
        steps = torch.full((2,), float(t))
        with torch.no_grad():
            expected = graph(x_t, steps).numpy()
        got = session.run([OUTPUT_NAME], {INPUT_NAMES[0]: x_t.numpy(), INPUT_NAMES[1]: steps.numpy()})[0]
        if not (np.isfinite(expected).all() and np.isfinite(got).all()):
            raise SinMDMError(f"the model gives non-finite outputs at t={t} (window {window}); nothing was written")
        worst = max(worst, float(np.abs(expected - got).max()))
    return worst


def export_run(
    run_dir: Path,
    out: Path,
    windows: list[int] | None = None,
    opset: int = DEFAULT_OPSET,
    force: bool = False,
    on_warning=None,
    checkpoint: str = "best",
) -> list[ExportResult]:
    """Write `<out stem>_w<W>.onnx` and its metadata sidecar `<out stem>_w<W>.json` for each
    window; verify each before it appears."""
    if opset not in SUPPORTED_OPSETS:
        raise SinMDMError(f"opset {opset} is not supported: use one of {SUPPORTED_OPSETS}")
    model, config = load_trained_model(Path(run_dir), checkpoint=checkpoint)
    if not config.get("finished"):
        raise SinMDMError(
            f"{run_dir} has no finished checkpoint (step {config['step']} of {config['steps']}): "
            "finish training with `sinmdm train ... --resume`"
        )
    trained_window, field = int(config["window"]), int(config["receptive_field"])
    windows = windows or [trained_window]
    for window in windows:
        if window < field:
            raise SinMDMError(f"window {window} is shorter than the model's receptive field ({field} frames)")
    targets = {w: window_path(Path(out), w) for w in windows}
    names = [name for path in targets.values() for name in (path.name, sidecar_path(path).name)]
    # every check of the outputs before the export work; all windows and sidecars appear together
    with OutputSet(Path(out).parent, names, force=force,
                   estimate_bytes=4 * int(config["parameters"]) * len(targets)) as output:
        results = [_export_window(model, config, window, path, output, opset, on_warning) for window, path in targets.items()]
        output.commit()
    return results


def _export_window(model: torch.nn.Module, config: dict, window: int, path: Path, output: OutputSet, opset: int,
                   on_warning) -> ExportResult:
    """Export, check and write (to `output`'s temp files) the graph for one window and its sidecar."""
    trained_window, field = int(config["window"]), int(config["receptive_field"])
    features = int(config["model"]["features"])
    graph = _Graph(model).eval()
    if window != trained_window and on_warning:
        on_warning(
            f"window {window} differs from the training length {trained_window}: GroupNorm spans the "
            "window, so quality drops (a pilot lost coverage from 88 % to 72 % at twice the length)"
        )
    onnx_model = _to_onnx(graph, features, window, opset)
    ops = _check_graph(onnx_model)
    metadata = encode_metadata({
        "codec": config["codec"],
        "start_position": config.get("start_position"),
        "alphas_cumprod": cosine_alphas_cumprod().tolist(),
        "schedule": config["schedule"],
        "window": window,
        "trained_window": trained_window,
        "receptive_field": field,
        "model": config["model"],
        "model_id": weights_id(model),
        "velocity_unit": config["train"].get("velocity_unit", "frame"),  # runtime.features.model_scale
        **({"heading_frame": config["heading_frame"]} if config.get("heading_frame") else {}),  # runtime.heading
        # the sampler settings measured with these weights (`sinmdm-run sample` uses them)
        "sampling_defaults": {k: config["sampling"][k] for k in ("steps", "hop", "smooth") if k in config["sampling"]}
        if config.get("sampling") else None,
        "provenance": {
            "clip": config["clip"]["name"],
            "clip_sha256": config["clip"]["sha256"],
            "preset": config["train"]["preset"],
            "steps": config["step"],
            "checkpoint": config["chosen"],
            "sampling_scores": (config.get("sampling") or {}).get("scores"),
            "loss": config["loss"],
            "train": config["train"],
            "exported": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            "sinmdm_version": __version__,
            "torch_version": torch.__version__,
        },
    })
    entry = onnx_model.metadata_props.add()
    entry.key, entry.value = METADATA_KEY, metadata
    onnx_model.producer_name, onnx_model.producer_version = "sinmdm", __version__
    data = onnx_model.SerializeToString()
    difference = _parity(data, graph, features, window)
    if difference > PARITY_TOLERANCE:
        raise SinMDMError(
            f"exported graph for window {window} disagrees with torch by {difference:.2e} (> {PARITY_TOLERANCE:g}); "
            "nothing was written"
        )
    output.write_bytes(path.name, data)
    output.write_text(sidecar_path(path).name, metadata)
    return ExportResult(path, window, difference, opset, onnx_model.ir_version, ops, len(data))
