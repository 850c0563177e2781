"""Writing a generation's outputs: the sample files of a command appear together or not at all.

Every check (names, directory, existing files, the writers an output needs) happens in
`plan_sample_outputs`, before any sampling. The runtime does not import the preview package:
GLB and GIF writers are handed in (the CLI's come from sinmdm/cli/writers.py)."""

from __future__ import annotations

import io
import os
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Mapping, Sequence

import numpy as np

from .atomic import OutputSet, check_plain_name
from .bvh import BVH, bvh_text_chunks
from .errors import OptionError, SinMDMError

if TYPE_CHECKING:
    from .generate import GenerationResult
    from .model import MotionModel

FORMATS = ("bvh", "glb")
BVH_BYTES_PER_VALUE = 12  # "%.6f" and a space: a BVH's size is about this per channel and frame
PREVIEW_EXTRA = "pip install 'sinmdm[preview]'"


def _npz_bytes(model: MotionModel, features: np.ndarray, clip: BVH) -> bytes:
    from .animation import animation_from_bvh, global_positions

    buffer = io.BytesIO()
    positions = global_positions(animation_from_bvh(clip)) * model.codec.scale
    np.savez_compressed(buffer, features=features, positions_m=positions.astype(np.float32),
                        joints=np.array(clip.skeleton.names), fps=model.codec.fps)
    return buffer.getvalue()


def _needed_writers(fmt: str, preview: bool, writers: Mapping[str, Callable] | None) -> dict[str, Callable]:
    if fmt not in FORMATS:
        raise OptionError("format", f"unknown format '{fmt}': use bvh or glb")
    needed = {"glb": fmt == "glb", "gif": preview}
    what = {"glb": "--format glb", "gif": "--preview"}
    available = dict(writers or {})
    for kind, wanted in needed.items():
        if wanted and kind not in available:
            raise SinMDMError(f"{what[kind]} needs the preview extra: {PREVIEW_EXTRA}")
    return available


class SampleOutputs:
    """The planned files of one generation: samples (and .npz) as one set, the preview GIF as another."""

    def __init__(self, samples: OutputSet, stems: list[str], fmt: str, npz: bool, preview: OutputSet | None,
                 writers: dict[str, Callable]) -> None:
        self.samples = samples
        self.stems = stems
        self.fmt = fmt
        self.npz = npz
        self.preview = preview
        self.writers = writers
        self.paths: list[Path] = samples.paths + (preview.paths if preview else [])

    def __enter__(self) -> "SampleOutputs":
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    def close(self) -> None:
        self.samples.close()
        if self.preview is not None:
            self.preview.close()

    def _write_clip(self, stem: str, clip: BVH) -> None:
        if self.fmt == "bvh":
            self.samples.write_chunks(f"{stem}.bvh", bvh_text_chunks(clip))
        else:
            self.samples.write(f"{stem}.glb", lambda tmp: self.writers["glb"](clip, tmp))

    def write(self, model: MotionModel, result: GenerationResult) -> list[Path]:
        """All sample files together or none; then the preview, so its failure never loses them."""
        if len(result.clips) != len(self.stems):
            raise ValueError(f"planned {len(self.stems)} samples, got {len(result.clips)}")
        try:
            with self.samples:
                for stem, features, clip in zip(self.stems, result.features, result.clips):
                    self._write_clip(stem, clip)
                    if self.npz:
                        self.samples.write_bytes(f"{stem}.npz", _npz_bytes(model, features, clip))
                written = self.samples.commit()
            if self.preview is not None:
                written += self._write_preview(result.clips)
        finally:
            self.close()
        return written

    def _write_preview(self, clips: list[BVH]) -> list[Path]:
        with self.preview as preview:
            try:
                preview.write(preview.names[0], lambda tmp: self.writers["gif"](clips, tmp))
                return preview.commit()
            except Exception as exc:  # the samples are safe: say so, whatever broke the preview
                reason = str(exc) if isinstance(exc, SinMDMError) else f"{type(exc).__name__}: {exc}"
                raise SinMDMError(f"the preview failed ({reason}); the {len(self.samples.paths)} sample "
                                  f"file(s) were written to {self.samples.directory}") from None


def plan_sample_outputs(
    out_dir: str | os.PathLike,
    name: str,
    seeds: Sequence[int],
    *,
    fmt: str = "bvh",
    npz: bool = False,
    preview: bool = False,
    force: bool = False,
    writers: Mapping[str, Callable] | None = None,
    values_per_sample: int = 0,
) -> SampleOutputs:
    """Check every output of a generation before sampling: names, directory, existing files, writers,
    and free space for `values_per_sample` (frames x channels) BVH values of each sample."""
    available = _needed_writers(fmt, preview, writers)
    check_plain_name(name)
    stems = [f"{name}_{seed:04d}" for seed in seeds]
    names = [f"{stem}.{ext}" for stem in stems for ext in ([fmt, "npz"] if npz else [fmt])]
    estimate = len(stems) * values_per_sample * BVH_BYTES_PER_VALUE
    samples = OutputSet(out_dir, names, force=force, estimate_bytes=estimate)
    gif = OutputSet(out_dir, [f"{name}_preview.gif"], force=force) if preview else None
    return SampleOutputs(samples, stems, fmt, npz, gif, available)


def write_outputs(
    model: MotionModel,
    result: GenerationResult,
    out_dir: str | os.PathLike,
    name: str = "sample",
    fmt: str = "bvh",
    npz: bool = False,
    preview: bool = False,
    force: bool = False,
    writers: Mapping[str, Callable] | None = None,
) -> list[Path]:
    """Write every clip (and extras); all sample files appear together or not at all."""
    planned = plan_sample_outputs(out_dir, name, result.seeds, fmt=fmt, npz=npz, preview=preview, force=force,
                                  writers=writers)
    return planned.write(model, result)
