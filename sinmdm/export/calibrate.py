"""Measure an exported model's sampling defaults against its own clip and store them in
its metadata (with its contact joints' resting heights in the clip when it lacks them):
what the watched trainer does at the end of a run, for a model that was exported without it (the bundled demo, models of the `paper` preset) or to re-measure
with more samples. Only the metadata changes; the graph is written back unchanged."""

from __future__ import annotations

import os
from datetime import datetime, timezone
from pathlib import Path

import onnx

from ..eval.balance import CheckSettings, ClipScorer, choose_sampling
from ..runtime.animation import global_positions
from ..runtime.atomic import OutputSet
from ..runtime.contacts import resting_heights
from ..runtime.errors import SinMDMError
from ..runtime.features import clip_animation
from ..runtime.model import load_model
from ..runtime.model_format import sidecar_path
from .model_files import learned_clip, one_folder, write_with_metadata


def clip_resting_heights(model, reference) -> tuple[float, ...]:
    """The resting heights (metres) of the model's contact joints in its clip, as training
    records them (runtime.contacts.resting_heights)."""
    codec = model.codec
    animation = clip_animation(reference, codec.fps, codec.resample)
    positions = global_positions(animation)[:, list(codec.contact_joints)] * codec.scale
    return resting_heights(positions, codec.fps, codec.contact_speed, codec.up_axis)


def trained_check_cleanup(model) -> bool:
    """Whether the run's quality checks sampled with the foot cleanup (`--check-cleanup`): calibration
    measures the same way unless told otherwise, so its choice and the run's agree."""
    return bool(((model.metadata.get("provenance") or {}).get("train") or {}).get("check_cleanup", False))


def calibrate_model(paths: list[str | os.PathLike], clip: str | os.PathLike, samples: int = CheckSettings.samples,
                    source_fps: float | None = None, threads: int | None = None, cleanup: bool | None = None) -> dict:
    """Choose the model's sampling defaults (`choose_sampling`) with `samples` motions per
    setting, sampled with the foot cleanup or not (`cleanup`; None: as the run's checks did),
    write them into every window's metadata and sidecar, and return the choice."""
    if samples < 2:
        raise SinMDMError(f"--samples must be at least 2 (diversity compares samples), got {samples}")
    model = load_model(paths, threads=threads)
    reference = learned_clip(model, clip, "its defaults are measured against that clip", source_fps)
    cleanup = trained_check_cleanup(model) if cleanup is None else cleanup
    scorer = ClipScorer(reference, CheckSettings(samples=samples, cleanup=cleanup), fps=model.codec.fps,
                        window=model.trained_window)
    chosen = {**choose_sampling(model, scorer, model.trained_window), "cleanup": cleanup}
    files = [Path(p) for p in paths]
    names = [name for path in files for name in (path.name, sidecar_path(path).name)]
    directory = one_folder(files, "calibrate")
    calibrated = {"date": datetime.now(timezone.utc).isoformat(timespec="seconds"), "samples": samples,
                  "cleanup": cleanup, "trials": chosen["trials"]}

    floors = None if model.codec.contact_floors is not None else clip_resting_heights(model, reference)

    def change(document: dict) -> None:
        document["sampling_defaults"] = {k: chosen[k] for k in ("steps", "hop", "smooth")}
        if floors is not None:  # a model trained before they were recorded: the cleanup's floor
            document["codec"]["contact_floors"] = list(floors)
        document["provenance"] = {**document["provenance"], "sampling_scores": chosen["scores"],
                                  "calibrated": calibrated}

    with OutputSet(directory, names, force=True) as output:
        for path in files:
            write_with_metadata(output, path.name, onnx.load(str(path)), path, change)
        output.commit()
    return chosen
