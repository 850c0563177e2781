"""Golden test vectors for ports of the sampler (docs/runtime.md): one sample's whole
chain, recorded from the real sampler (`sample_loop`, `WindowedDenoiser`, `draw`)
through a recording denoiser and recording random streams, and its decoding.

Arrays are little-endian float32 raw files (`.f32`, C order), described with their
shapes in manifest.json; the model's metadata document lies beside them as
metadata.json. Step arrays are in the order the loop runs: index k is chain step
S - 1 - k (timestep `denoiser_timesteps[k]`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import __version__
from .animation import global_positions
from .atomic import OutputSet, file_sha256
from .errors import OptionError
from .model import MotionModel
from .options import SamplingOptions
from .rig import skeleton_extent
from .sampler import STATE_DTYPE, WindowedDenoiser, blend_weights, draw, plan_sampling, sample_loop, to_features
from .schedule import Schedule
from .smoothing import smooth_frames

FORMAT_NAME = "sinmdm-vectors"
FORMAT_VERSION = 1
MANIFEST = "manifest.json"
METADATA = "metadata.json"
MAX_BYTES = 1 << 30  # vectors are test fixtures: a gigabyte is far past any useful case
DEFAULT_FRAMES = 160


class RecordingStream:
    """A numpy Generator whose standard normals are also kept, in the order drawn
    (the only method `draw` uses)."""

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.drawn: list[np.ndarray] = []

    def standard_normal(self, *args, **kwargs) -> np.ndarray:
        values = self.rng.standard_normal(*args, **kwargs)
        self.drawn.append(np.array(values, dtype=np.float64).ravel())
        return values

    def normals(self) -> np.ndarray:
        return np.concatenate(self.drawn) if self.drawn else np.zeros(0)


class RecordingDenoiser:
    """The windowed denoiser, its input x_t and blended x0_hat kept at every call."""

    def __init__(self, denoise: WindowedDenoiser) -> None:
        self.denoise = denoise
        self.x_t: list[np.ndarray] = []
        self.x0_hat: list[np.ndarray] = []
        self.timesteps: list[int] = []

    def __call__(self, x_t: np.ndarray, t: int) -> np.ndarray:
        x0 = self.denoise(x_t, t)
        self.x_t.append(x_t[0].copy())
        self.x0_hat.append(x0[0].copy())
        self.timesteps.append(int(t))
        return x0


@dataclass
class Plan:
    """What sample_features runs on (`plan_sampling`), for one sample, and what it will write."""

    frames: int
    options: SamplingOptions  # resolved: steps and hop filled in
    loop: bool
    margin: int
    denoise: WindowedDenoiser
    schedule: Schedule

    def bytes(self, model: MotionModel) -> int:
        per_step = 3 * model.graph_width * self.denoise.frames  # x_t, x0_hat, noise
        decoded = self.frames * (2 * model.features + model.codec.skeleton.num_joints * 15)  # features, smoothed, joints
        return 4 * (per_step * len(self.schedule.timesteps) + 2 * model.features * self.denoise.frames + decoded)


def plan(model: MotionModel, frames: int, options: SamplingOptions, loop: bool = False) -> Plan:
    """One sample (seed `options.seed`) as `sample_features` would make it; every option checked."""
    if options.count != 1:
        raise OptionError("count", f"vectors record one sample, got {options.count}")
    options, margin, denoise, schedule = plan_sampling(model, frames, options, loop)
    return Plan(frames, options, loop, margin, denoise, schedule)


@dataclass
class Recording:
    plan: Plan
    arrays: dict[str, np.ndarray]  # name -> array, written as float32
    timesteps: list[int]  # what the denoiser saw, in loop order


def record(model: MotionModel, planned: Plan) -> Recording:
    """Run the planned sample through the real loop, its chain kept, and decode it."""
    options, margin, frames, schedule = planned.options, planned.margin, planned.frames, planned.schedule
    length = planned.denoise.frames
    stream = RecordingStream(np.random.default_rng(options.seed))
    x_T = draw([stream], (model.graph_width, length), STATE_DTYPE)
    recorder = RecordingDenoiser(planned.denoise)
    x_0 = sample_loop(recorder, schedule, x_T.copy(), [stream], options.sampler, options.eta)
    features = to_features(x_0[:, :, margin : margin + frames], model.graph_space, planned.loop)[0]

    size = model.graph_width * length
    normals = stream.normals()
    steps = len(schedule.timesteps)
    if normals.size != size * steps:
        raise AssertionError(f"the sampler drew {normals.size} normals, expected {size * steps}")
    noise = normals[size:].reshape(steps - 1, model.graph_width, length).astype(STATE_DTYPE)
    smoothed = smooth_frames(features[None], options.smooth, wrap=planned.loop)[0]
    animation = model.codec.decode(smoothed, model.start_position)
    arrays = {
        "x_T": x_T[0],
        "noise": noise,
        "x_t": np.stack(recorder.x_t),
        "x0_hat": np.stack(recorder.x0_hat),
        "x_0": x_0[0],
        "features": features,
        "smoothed": smoothed,
        "local_rotations": animation.rotations,
        "local_translations": animation.translations,
        "positions": global_positions(animation),
    }
    return Recording(planned, arrays, recorder.timesteps)


ARRAY_NOTES = {
    "x_T": "the initial noise: the first F*L normals of the sample's stream",
    "noise": "row k: the normals drawn at loop iteration k (chain step S-1-k), after denoising; none at the last step",
    "x_t": "row k: x fed to the windowed denoiser at loop iteration k (row 0 is x_T)",
    "x0_hat": "row k: the blended x0 prediction at loop iteration k",
    "x_0": "the loop's result, margins included",
    "features": "x_0 without the margins, divided by the model scale (metadata velocity_unit), transposed to (frames, F): what sample_features returns",
    "smoothed": "features smoothed over frames (options.smooth, docs/runtime.md 'Smoothing'): what generate decodes",
    "local_rotations": "MotionCodec.decode of smoothed: local rotation matrices, acting on column vectors",
    "local_translations": "MotionCodec.decode of smoothed: local translations, file units",
    "positions": "forward kinematics of the decoded animation: world joint positions, file units",
}


def manifest(model: MotionModel, model_path: Path, recording: Recording) -> dict:
    planned = recording.plan
    options, denoise, schedule, frames = planned.options, planned.denoise, planned.schedule, planned.frames
    c1, c2, log_var = schedule.posterior()
    codec = model.codec
    return {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "sinmdm_version": __version__,
        "model": {"file": model_path.name, "sha256": file_sha256(model_path), "model_id": model.metadata["model_id"]},
        "metadata": METADATA,
        "options": {"frames": frames, "seed": options.seed, "sampler": options.sampler, "steps": options.steps,
                    "eta": options.eta, "hop": denoise.hop, "margin": planned.margin, "loop": planned.loop,
                    "smooth": options.smooth},
        "random": "numpy PCG64 (np.random.default_rng(seed)) standard normals: a port reads them from x_T and noise",
        "state_dtype": np.dtype(STATE_DTYPE).name,
        "length": denoise.frames,
        "features": model.features,
        "graph_width": model.graph_width,  # the chain's channels: the features, and a heading-frame model's turn rate
        "cut": [planned.margin, planned.margin + frames],
        "window": denoise.window,
        "window_starts": denoise.starts.tolist(),
        "blend_weights": blend_weights(denoise.window).tolist(),
        "schedule": {
            "timesteps": schedule.timesteps.tolist(),
            "alphas_cumprod": schedule.alphas_cumprod.tolist(),
            "c1": c1.tolist(),
            "c2": c2.tolist(),
            "log_variance": log_var.tolist(),
        },
        "denoiser_timesteps": recording.timesteps,
        "start_position": model.start_position.tolist(),
        "metres_per_unit": codec.scale,
        "figure_size": skeleton_extent(codec.skeleton),
        "joints": list(codec.skeleton.names),
        "arrays": {
            name: {"file": f"{name}.f32", "shape": list(array.shape), "dtype": "float32", "byte_order": "little",
                   "note": ARRAY_NOTES[name]}
            for name, array in recording.arrays.items()
        },
    }


def _format_manifest(document: dict) -> str:
    """One line per key, two levels deep: readable, and the long number lists stay on one line."""
    def block(value: dict, indent: str) -> str:
        lines = [f"{indent}{json.dumps(k)}: {json.dumps(v, separators=(',', ':'))}" for k, v in value.items()]
        return "{\n" + ",\n".join(lines) + "\n" + indent[:-1] + "}"

    lines = [f" {json.dumps(k)}: {block(v, '  ') if isinstance(v, dict) else json.dumps(v)}" for k, v in document.items()]
    return "{\n" + ",\n".join(lines) + "\n}\n"


def _check_directory(out: Path, force: bool) -> None:
    if out.exists() and not out.is_dir():
        raise OptionError("out", f"{out} exists and is not a directory")
    if out.is_dir() and not force and any(out.iterdir()):
        raise OptionError("out", f"{out} is not empty; pass --force to write into it (or choose another --out)")


def write_vectors(model: MotionModel, model_path: str | Path, out: str | Path, frames: int = DEFAULT_FRAMES,
                  options: SamplingOptions = SamplingOptions(), loop: bool = False, force: bool = False) -> dict:
    """Record one sample and write its vectors into `out` (all files or none); the manifest."""
    out, model_path = Path(out), Path(model_path)
    _check_directory(out, force)
    planned = plan(model, frames, options, loop)
    size = planned.bytes(model)
    if size > MAX_BYTES:
        raise OptionError("frames", f"vectors of {frames} frames and {planned.options.steps} steps would take "
                                    f"{size / 1e9:.1f} GB: use fewer --frames or --steps")
    names = [MANIFEST, METADATA] + [f"{name}.f32" for name in ARRAY_NOTES]
    with OutputSet(out, names, force=force, estimate_bytes=size) as files:
        recording = record(model, planned)
        document = manifest(model, model_path, recording)
        for name, array in recording.arrays.items():
            files.write_bytes(f"{name}.f32", np.ascontiguousarray(array, dtype="<f4").tobytes())
        files.write_text(METADATA, json.dumps(model.metadata, separators=(",", ":")) + "\n")
        files.write_text(MANIFEST, _format_manifest(document))
        files.commit()
    return document


def read_array(directory: str | Path, document: dict, name: str) -> np.ndarray:
    """An array of a vectors directory, as its manifest describes it."""
    entry = document["arrays"][name]
    return np.fromfile(Path(directory) / entry["file"], dtype="<f4").reshape(entry["shape"])
