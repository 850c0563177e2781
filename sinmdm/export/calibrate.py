"""Measure an exported model's sampling defaults against its own clip and store them in
its metadata: what the watched trainer does at the end of a run, for a model that was
exported without it (the bundled demo, models of the `paper` preset) or to re-measure
with more samples. Only the metadata changes; the graph is written back unchanged."""

from __future__ import annotations

import os
from datetime import datetime, timezone
from pathlib import Path

import onnx

from ..eval.balance import CheckSettings, ClipScorer, choose_sampling
from ..runtime.atomic import OutputSet
from ..runtime.errors import SinMDMError
from ..runtime.model import load_model
from ..runtime.model_format import sidecar_path
from .model_files import learned_clip, one_folder, write_with_metadata


def calibrate_model(paths: list[str | os.PathLike], clip: str | os.PathLike, samples: int = CheckSettings.samples,
                    source_fps: float | None = None, threads: int | None = None) -> dict:
    """Choose the model's sampling defaults (`choose_sampling`) with `samples` motions per
    setting, write them into every window's metadata and sidecar, and return the choice."""
    if samples < 2:
        raise SinMDMError(f"--samples must be at least 2 (diversity compares samples), got {samples}")
    model = load_model(paths, threads=threads)
    reference = learned_clip(model, clip, "its defaults are measured against that clip", source_fps)
    scorer = ClipScorer(reference, CheckSettings(samples=samples), fps=model.codec.fps, window=model.trained_window)
    chosen = choose_sampling(model, scorer, model.trained_window)
    files = [Path(p) for p in paths]
    names = [name for path in files for name in (path.name, sidecar_path(path).name)]
    directory = one_folder(files, "calibrate")
    calibrated = {"date": datetime.now(timezone.utc).isoformat(timespec="seconds"), "samples": samples,
                  "trials": chosen["trials"]}

    def change(document: dict) -> None:
        document["sampling_defaults"] = {k: chosen[k] for k in ("steps", "hop", "smooth")}
        document["provenance"] = {**document["provenance"], "sampling_scores": chosen["scores"],
                                  "calibrated": calibrated}

    with OutputSet(directory, names, force=True) as output:
        for path in files:
            write_with_metadata(output, path.name, onnx.load(str(path)), path, change)
        output.commit()
    return chosen
