"""Loading exported denoisers: one or more `.onnx` files of the same model
(one per window length), validated from their own metadata."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import ModelError, OptionError, SinMDMError
from .features import MotionCodec
from .graph_space import GraphSpace, graph_space
from .heading import trajectory_rotation
from .model_format import INPUT_NAMES, METADATA_KEY, OUTPUT_NAME, decode_metadata
from .options import check_whole

DEMO_MODEL = Path(__file__).resolve().parent / "demo" / "stomper_w64.onnx"


def _session_options(threads: int | None):
    import onnxruntime as ort

    options = ort.SessionOptions()
    options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    options.intra_op_num_threads = threads or os.cpu_count() or 1
    options.inter_op_num_threads = 1
    options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    options.log_severity_level = 3
    return options


@dataclass
class OnnxDenoiser:
    """One exported graph: x0 = denoise(x_t (N, F, W), t (N,))."""

    path: Path
    window: int
    session: object

    def __call__(self, x_t: np.ndarray, t: np.ndarray) -> np.ndarray:
        return self.session.run(
            [OUTPUT_NAME], {INPUT_NAMES[0]: x_t.astype(np.float32, copy=False), INPUT_NAMES[1]: t.astype(np.float32, copy=False)}
        )[0]


@dataclass
class MotionModel:
    codec: MotionCodec
    alphas_cumprod: np.ndarray  # float64 (1000,)
    receptive_field: int
    trained_window: int
    denoisers: dict[int, OnnxDenoiser]
    metadata: dict
    start_position: np.ndarray = field(default_factory=lambda: np.zeros(2))

    @property
    def windows(self) -> list[int]:
        return sorted(self.denoisers)

    @property
    def features(self) -> int:
        return self.codec.width

    @property
    def graph_width(self) -> int:
        return self.graph_space.width

    @property
    def velocity_unit(self) -> str:
        """What the graph's root velocity channels count in: "frame" (the paper: metres per
        frame) or "second" (metres per second, `sinmdm train --velocity-unit second`; see
        model_scale, which refuses any other value)."""
        return self.metadata.get("velocity_unit", "frame")

    @property
    def graph_space(self) -> GraphSpace:
        """How the graph sees features: the root velocity's unit, and the heading frame when
        the model was trained in it (`sinmdm train --root-frame heading`)."""
        return graph_space(self.codec, self.metadata)

    @property
    def default_steps(self) -> int:
        """Denoising steps measured with these weights at training (export metadata), else 50."""
        from .sampler import DEFAULT_STEPS

        value = (self.metadata.get("sampling_defaults") or {}).get("steps")
        return int(value) if isinstance(value, int) and 1 <= value <= len(self.alphas_cumprod) else DEFAULT_STEPS

    @property
    def default_smooth(self) -> float:
        """Frames of smoothing measured with these weights (export metadata), else DEFAULT_SMOOTH."""
        from .options import DEFAULT_SMOOTH

        value = (self.metadata.get("sampling_defaults") or {}).get("smooth")
        return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else DEFAULT_SMOOTH

    def default_hop(self, frames: int) -> int | None:
        """The measured hop (frames at the training window), scaled to the window `frames`
        uses; None (half a window) when the model carries none."""
        value = (self.metadata.get("sampling_defaults") or {}).get("hop")
        if not isinstance(value, int) or not 1 <= value <= self.trained_window:
            return None
        window = self.denoiser_for(frames).window
        return max(1, min(window, round(value * window / self.trained_window)))

    def denoiser_for(self, frames: int) -> OnnxDenoiser:
        """The trained window when present, else the smallest window that covers `frames`
        (or the largest one for longer requests)."""
        if self.trained_window in self.denoisers:
            return self.denoisers[self.trained_window]
        covering = [w for w in self.windows if w >= frames]
        return self.denoisers[covering[0] if covering else self.windows[-1]]


MAX_THREADS = 256


# `provider` names -> onnxruntime execution providers, each used where its onnxruntime build is
# installed (onnxruntime-gpu, onnxruntime-openvino, onnxruntime-directml); CPU is the tested path.
PROVIDERS = {"cpu": "CPUExecutionProvider", "cuda": "CUDAExecutionProvider",
             "openvino": "OpenVINOExecutionProvider", "directml": "DmlExecutionProvider",
             "coreml": "CoreMLExecutionProvider"}


def _check_threads(threads: int | None) -> int | None:
    return None if threads is None else check_whole("threads", threads, 1, MAX_THREADS)


def execution_providers(provider: str) -> list[str]:
    """onnxruntime's providers for `provider`, CPU behind it for any operator it lacks."""
    import onnxruntime as ort

    if provider not in PROVIDERS:
        raise OptionError("provider", f"unknown provider {provider!r}: use one of {', '.join(PROVIDERS)}")
    available = ort.get_available_providers()
    if PROVIDERS[provider] not in available:
        names = [name for name, ep in PROVIDERS.items() if ep in available]
        raise OptionError("provider", f"{provider} is not available in this onnxruntime build "
                                      f"(available: {', '.join(names)})")
    return list(dict.fromkeys([PROVIDERS[provider], PROVIDERS["cpu"]]))


def _open_session(path: Path, options, providers: list[str]) -> object:
    """The one InferenceSession of a file: the denoiser runs on it and its metadata is read from it."""
    import onnxruntime as ort

    if not path.is_file():
        raise SinMDMError(f"model file {path} does not exist")
    try:
        return ort.InferenceSession(str(path), sess_options=options, providers=providers)
    except Exception as exc:  # onnxruntime raises its own exception types for damaged files
        first_line = str(exc).strip().splitlines()[0][:160] if str(exc).strip() else type(exc).__name__
        raise ModelError(f"{path} is not a readable ONNX model ({first_line})") from None


def _read_codec(metadata: dict, path: Path) -> MotionCodec:
    try:
        return MotionCodec.from_dict(metadata["codec"])
    except (KeyError, TypeError, ValueError, IndexError, SinMDMError) as exc:
        raise ModelError(f"{path}: the skeleton or feature layout in its metadata is invalid ({exc})") from None


def _check_graph(denoiser: OnnxDenoiser, features: int, timesteps: int) -> None:
    """The graph must be what its metadata says: inputs (x_t, t), one output x0 of x_t's
    shape (batch, features, window), and a denoiser: one probe at a middle timestep must
    give finite values that are not its input returned unchanged."""
    session, path, window = denoiser.session, denoiser.path, denoiser.window
    inputs = [i.name for i in session.get_inputs()]
    outputs = [o.name for o in session.get_outputs()]
    if inputs != list(INPUT_NAMES) or outputs != [OUTPUT_NAME]:
        raise ModelError(f"{path} has inputs {inputs} and outputs {outputs}, expected {list(INPUT_NAMES)} and {[OUTPUT_NAME]}")
    expected = (features, window)
    for what, node in (("input x_t", session.get_inputs()[0]), ("output x0", session.get_outputs()[0])):
        declared = tuple(node.shape[1:]) if node.shape is not None else ()
        if len(node.shape or ()) != 3 or any(isinstance(d, int) and d != e for d, e in zip(declared, expected)):
            raise ModelError(f"{path}: its {what} has shape {node.shape}, but its metadata says (batch, {features}, {window})")
    x_t = np.random.default_rng(0).standard_normal((1, features, window)).astype(np.float32)
    try:
        x0 = np.asarray(denoiser(x_t, np.array([timesteps // 2], dtype=np.float32)))
    except Exception as exc:  # onnxruntime's own types: a graph that cannot run these shapes
        raise ModelError(f"{path}: its graph does not run on (1, {features}, {window}) inputs ({str(exc).strip()[:160]})") from None
    if x0.shape != x_t.shape:
        raise ModelError(f"{path}: its graph returns shape {x0.shape} for an input of shape {x_t.shape}")
    if not np.isfinite(x0).all():
        raise ModelError(f"{path}: its graph returns NaN or infinite values")
    if np.array_equal(x0, x_t):
        raise ModelError(f"{path}: its graph returns its input unchanged: not a trained denoiser")


def _graph_width(codec: MotionCodec, metadata: dict, path: Path) -> int:
    """The channels the graph sees: the features, and the turn rate of a heading-frame model."""
    if metadata.get("heading_frame") is not None and trajectory_rotation(codec) is None:
        raise ModelError(f"{path}: its metadata names a heading frame, but its trajectory joint has no rotation features")
    return graph_space(codec, metadata).width


def load_model(paths: list[str | os.PathLike] | str | os.PathLike | None = None, threads: int | None = None,
               provider: str = "cpu") -> MotionModel:
    """Load one model from its `.onnx` windows (default: the bundled demo model), run by
    onnxruntime's `provider` (a key of PROVIDERS)."""
    if paths is None or (isinstance(paths, list) and not paths):
        paths = [DEMO_MODEL]
    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    options = _session_options(_check_threads(threads))
    providers = execution_providers(provider)
    first: dict | None = None
    denoisers: dict[int, OnnxDenoiser] = {}
    for raw in paths:
        path = Path(raw)
        session = _open_session(path, options, providers)
        metadata = decode_metadata(session.get_modelmeta().custom_metadata_map.get(METADATA_KEY), str(path))
        if first is None:
            first, codec = metadata, _read_codec(metadata, path)
        elif metadata["model_id"] != first["model_id"]:
            raise ModelError(f"{path} belongs to another model than {Path(paths[0])}: windows of different models cannot be mixed")
        window = metadata["window"]
        if window in denoisers:
            raise ModelError(f"{path} repeats window {window}")
        denoisers[window] = OnnxDenoiser(path, window, session)
        _check_graph(denoisers[window], _graph_width(codec, first, path), len(first["alphas_cumprod"]))
    start = first.get("start_position") or [0.0, 0.0]
    return MotionModel(
        codec=codec,
        alphas_cumprod=np.asarray(first["alphas_cumprod"], dtype=np.float64),
        receptive_field=first["receptive_field"],
        trained_window=first.get("trained_window", first["window"]),
        denoisers=denoisers,
        metadata=first,
        start_position=np.asarray(start, dtype=np.float64),
    )
