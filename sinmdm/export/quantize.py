"""A mixed-precision copy of an exported model: int8 convolutions for every step but the
last, the float32 graph for the last one (t = 0), in one self-describing ONNX graph per window.

Why mixed: the convolutions are about 65 % of a denoiser call, and int8 (onnxruntime's
QLinearConv, static per-channel weights, activations calibrated on the model's own
sampling trajectories) runs them 1.5-2.2x faster. But the last step's x0 is the output
itself, and int8 there lands in it as frame-to-frame noise: int8 at every step took the
walk's jitter from 2.9x to 7.9x the clip's and the crab's coverage from 37 % to 18 %;
with the last step in float32 both score as the float32 graph at 10, 20 and 50 steps
(as does a float32 tail of 15 % of the schedule, which costs more; BENCHMARKS.md). So
each window's graph is `If(t[0] > 0, int8 branch, float32 branch)`: every runtime that
runs the graph runs the same mixed sampler, with no code of its own.

A copy is written only after a quality check: the same seeds sampled with both graphs at
the model's own settings, scored against the clip (`ClipScorer`); it is refused when its
balance falls more than BALANCE_TOLERANCE or its jitter rises more than JITTER_TOLERANCE.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import onnx
from onnx import helper

from ..eval.balance import BALANCE_TOLERANCE, CheckSettings, ClipScorer
from ..runtime.atomic import OutputSet, file_sha256
from ..runtime.errors import SinMDMError
from ..runtime.generate import generate
from ..runtime.model import MotionModel, OnnxDenoiser, load_model
from ..runtime.model_format import INPUT_NAMES, OUTPUT_NAME, sidecar_path
from ..runtime.options import SamplingOptions
from .model_files import learned_clip, one_folder, write_with_metadata

INT8_ABOVE_T = 0  # timesteps at or below it run the float32 branch: the last step of any chain
JITTER_TOLERANCE = 0.10  # relative rise of the jitter ratio that refuses the copy
CALIBRATION_SAMPLES = 4  # motions of the clip's length whose denoiser inputs calibrate the activations
CALIBRATION_SEED = 12345  # not the check's seeds: the check scores on trajectories it was not calibrated on


@dataclass
class _Recorder:
    """Stands in for a window's denoiser and keeps every input it is given."""

    inner: OnnxDenoiser
    inputs: list

    @property
    def window(self) -> int:
        return self.inner.window

    @property
    def path(self) -> Path:
        return self.inner.path

    def __call__(self, x_t: np.ndarray, t: np.ndarray) -> np.ndarray:
        self.inputs.append({INPUT_NAMES[0]: np.array(x_t, dtype=np.float32), INPUT_NAMES[1]: np.array(t, dtype=np.float32)})
        return self.inner(x_t, t)


def calibration_inputs(model: MotionModel, frames: int, samples: int = CALIBRATION_SAMPLES,
                       seed: int = CALIBRATION_SEED) -> dict[int, list[dict]]:
    """Per window: the (x_t, t) batches the float32 sampler feeds it at the model's own
    settings, `samples` motions of `frames` frames (at least the window) sampled with that
    window alone (a model samples with its trained window whenever it has it)."""
    recorded: dict[int, list[dict]] = {}
    for window, denoiser in model.denoisers.items():
        recorded[window] = []
        alone = dataclasses.replace(model, denoisers={window: _Recorder(denoiser, recorded[window])})
        generate(alone, max(frames, window), SamplingOptions(count=samples, seed=seed, cleanup=False))
    return recorded


def quantized_convolutions(source: Path, inputs: list[dict]) -> onnx.ModelProto:
    """The float32 graph with every Conv in int8 (QOperator: QLinearConv), weights per
    output channel, activations' ranges from `inputs`."""
    from onnxruntime.quantization import CalibrationDataReader, QuantFormat, QuantType, quantize_static

    class Reader(CalibrationDataReader):
        def __init__(self):
            self.batches = iter(inputs)

        def get_next(self):
            return next(self.batches, None)

    # Its advice to pre-process first is muted: the pre-processing's symbolic shape
    # inference fails on these graphs, and the quality check below is what decides.
    logging.disable(logging.WARNING)
    try:
        with tempfile.TemporaryDirectory() as scratch:
            target = Path(scratch) / "int8.onnx"
            quantize_static(str(source), str(target), Reader(), quant_format=QuantFormat.QOperator,
                            op_types_to_quantize=["Conv"], per_channel=True,
                            activation_type=QuantType.QUInt8, weight_type=QuantType.QInt8)
            return onnx.load(str(target))
    finally:
        logging.disable(logging.NOTSET)


def _branch(graph: onnx.GraphProto, prefix: str, name: str) -> onnx.GraphProto:
    """`graph` as an If branch: no inputs (x_t and t come from the outer graph), every
    other name prefixed so the two branches never share one."""
    outer = set(INPUT_NAMES)
    if any(attr.type in (onnx.AttributeProto.GRAPH, onnx.AttributeProto.GRAPHS) for n in graph.node for attr in n.attribute):
        raise SinMDMError("this graph has nested subgraphs: it cannot be made mixed-precision")

    def renamed(value: str) -> str:
        return value if not value or value in outer else prefix + value

    branch = onnx.GraphProto()
    branch.CopyFrom(graph)
    del branch.input[:]
    for node in branch.node:
        node.name = prefix + node.name
        node.input[:] = [renamed(v) for v in node.input]
        node.output[:] = [renamed(v) for v in node.output]
    for init in branch.initializer:
        init.name = renamed(init.name)
    for info in list(branch.value_info) + list(branch.output):
        info.name = renamed(info.name)
    branch.name = name
    return branch


def mixed_graph(float32: onnx.ModelProto, int8: onnx.ModelProto, above_t: int) -> onnx.ModelProto:
    """One graph: x0 = int8 branch when t > above_t, else the float32 branch."""
    graph = float32.graph
    constants = [helper.make_tensor("int8_above_t", onnx.TensorProto.FLOAT, [], [float(above_t)]),
                 helper.make_tensor("first", onnx.TensorProto.INT64, [], [0])]
    branches = {"int8": _branch(int8.graph, "int8/", "int8"), "fp32": _branch(graph, "fp32/", "fp32")}
    weights = []
    for branch in branches.values():
        # the branches' weights live in the outer graph (branches see outer names): onnxruntime
        # holds a subgraph's own initializers at 3-4x their size (146 MB against 39 for the walk)
        weights.extend(branch.initializer)
        del branch.initializer[:]
    nodes = [  # every window of a call is at the same step: t[0] is the step's timestep
        helper.make_node("Gather", [INPUT_NAMES[1], "first"], ["t_first"], axis=0, name="t_first"),
        helper.make_node("Greater", ["t_first", "int8_above_t"], ["noisy"], name="noisy"),
        helper.make_node("If", ["noisy"], [OUTPUT_NAME], name="precision",
                         then_branch=branches["int8"], else_branch=branches["fp32"]),
    ]
    combined = helper.make_graph(nodes, graph.name or "sinmdm", list(graph.input), list(graph.output),
                                 constants + weights)
    domains: dict[str, int] = {}
    for opset in list(float32.opset_import) + list(int8.opset_import):
        domains[opset.domain] = max(domains.get(opset.domain, 0), opset.version)
    model = helper.make_model(combined, opset_imports=[helper.make_opsetid(d, v) for d, v in domains.items()],
                              producer_name="sinmdm")
    model.ir_version = max(float32.ir_version, int8.ir_version)
    model.metadata_props.extend(float32.metadata_props)
    onnx.checker.check_model(model)
    return model


def mixed_name(path: Path) -> str:
    return f"{path.stem}_int8{path.suffix}"


def quantize_model(paths: list[str | os.PathLike], clip: str | os.PathLike, samples: int = 12,
                   source_fps: float | None = None, threads: int | None = None, force: bool = False,
                   out: str | os.PathLike | None = None) -> dict:
    """Write `<window>_int8.onnx` (and its sidecar) for each window of the model, in `out`
    (default: beside the model), after the quality check; return the check's figures.
    Refused (nothing written) when the mixed graph loses quality."""
    if samples < 2:
        raise SinMDMError(f"--samples must be at least 2 (diversity compares samples), got {samples}")
    files = [Path(p) for p in paths]
    model = load_model(files, threads=threads)
    if "int8_above_t" in (model.metadata.get("precision") or {}):
        raise SinMDMError(f"{files[0]} is already mixed-precision: quantize the float32 model it was made from")
    reference = learned_clip(model, clip, "the check scores against that clip", source_fps)
    beside = one_folder(files, "quantize")
    directory = beside if out is None else Path(out)
    targets = {p: mixed_name(p) for p in files}
    names = [n for t in targets.values() for n in (t, sidecar_path(Path(t)).name)]
    scorer = ClipScorer(reference, CheckSettings(samples=samples), fps=model.codec.fps, window=model.trained_window)

    with OutputSet(directory, names, force=force) as output:  # refuses existing outputs before the work
        inputs = calibration_inputs(model, scorer.frames)
        graphs: dict[Path, onnx.ModelProto] = {}
        for path in files:
            window = next(w for w, d in model.denoisers.items() if d.path == path)
            int8 = quantized_convolutions(path, inputs[window])
            graphs[path] = mixed_graph(onnx.load(str(path)), int8, INT8_ABOVE_T)
        with tempfile.TemporaryDirectory() as scratch:
            trial = []
            for path, graph in graphs.items():
                trial.append(Path(scratch) / path.name)
                onnx.save(graph, str(trial[-1]))
            checked = _check(model, load_model(trial, threads=threads), scorer)
        for path, graph in graphs.items():
            quantized = {"source": path.name, "source_sha256": file_sha256(path), **checked}

            def change(document: dict, quantized: dict = quantized) -> None:
                document["precision"] = {"int8_above_t": INT8_ABOVE_T}
                document["provenance"] = {**document["provenance"], "quantized": quantized}

            write_with_metadata(output, targets[path], graph, path, change)
        output.commit()
    return {**checked, "outputs": [str(directory / t) for t in targets.values()], "int8_above_t": INT8_ABOVE_T}


def _check(float32: MotionModel, mixed: MotionModel, scorer: ClipScorer) -> dict:
    """Both models on the scorer's seeds at the model's own settings; refuse a loss."""
    steps, hop = float32.default_steps, float32.default_hop(scorer.frames)
    before = scorer.check(float32, steps=steps, hop=hop)
    after = scorer.check(mixed, steps=steps, hop=hop)
    keys = ("coverage", "global_diversity", "local_diversity", "jitter_ratio", "balance", "check_seconds")
    figures = {"steps": steps, "hop": hop, "samples": scorer.settings.samples,
               "float32": {k: before[k] for k in keys}, "mixed": {k: after[k] for k in keys}}
    lost = before["balance"] - after["balance"]
    shakier = after["jitter_ratio"] > before["jitter_ratio"] * (1 + JITTER_TOLERANCE)
    if lost > BALANCE_TOLERANCE or shakier:
        raise SinMDMError(
            f"the int8 graph loses quality: balance {before['balance']:.3f} -> {after['balance']:.3f}, jitter "
            f"{before['jitter_ratio']:.2f}x -> {after['jitter_ratio']:.2f}x the clip's (limits: -{BALANCE_TOLERANCE:g}, "
            f"+{JITTER_TOLERANCE:.0%}); nothing written")
    return figures
