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
from ..runtime.atomic import OutputSet, file_sha256
from ..runtime.bvh import BVH, read_bvh
from ..runtime.errors import SinMDMError
from ..runtime.model import load_model
from ..runtime.model_format import METADATA_KEY, decode_metadata, encode_metadata, sidecar_path


def calibrate_model(paths: list[str | os.PathLike], clip: str | os.PathLike, samples: int = CheckSettings.samples,
                    source_fps: float | None = None, threads: int | None = None) -> dict:
    """Choose the model's sampling defaults (`choose_sampling`) with `samples` motions per
    setting, write them into every window's metadata and sidecar, and return the choice."""
    if samples < 2:
        raise SinMDMError(f"--samples must be at least 2 (diversity compares samples), got {samples}")
    model = load_model(paths, threads=threads)
    reference = read_bvh(clip)  # a missing or unreadable clip is refused here, in one line
    provenance = model.metadata["provenance"]
    expected = provenance.get("clip_sha256")
    if expected and file_sha256(clip) != expected:
        raise SinMDMError(f"{clip} is not the clip this model learned ({provenance.get('clip')!r}, sha256 "
                          f"{str(expected)[:12]}): its defaults are measured against that clip")
    if source_fps:
        reference = BVH(reference.skeleton, 1.0 / source_fps, reference.values, reference.path)
    scorer = ClipScorer(reference, CheckSettings(samples=samples), fps=model.codec.fps, window=model.trained_window)
    chosen = choose_sampling(model, scorer, model.trained_window)
    files = [Path(p) for p in paths]
    names = [name for path in files for name in (path.name, sidecar_path(path).name)]
    directory = files[0].parent
    if any(path.parent.resolve() != directory.resolve() for path in files):
        raise SinMDMError("calibrate the windows of a model in one folder")
    with OutputSet(directory, names, force=True) as output:
        for path in files:
            graph = onnx.load(str(path))
            entry = next(e for e in graph.metadata_props if e.key == METADATA_KEY)
            document = decode_metadata(entry.value, str(path))
            document["sampling_defaults"] = {"steps": chosen["steps"], "hop": chosen["hop"]}
            document["provenance"] = {
                **document["provenance"],
                "sampling_scores": chosen["scores"],
                "calibrated": {"date": datetime.now(timezone.utc).isoformat(timespec="seconds"), "samples": samples,
                               "trials": chosen["trials"]},
            }
            entry.value = encode_metadata({k: v for k, v in document.items() if k not in ("format", "format_version")})
            decode_metadata(entry.value, str(path))  # valid before anything is replaced
            output.write_bytes(path.name, graph.SerializeToString())
            output.write_text(sidecar_path(path).name, entry.value)
        output.commit()
    return chosen
