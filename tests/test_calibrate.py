"""`sinmdm calibrate`: an exported model's sampling defaults measured against its clip and
written into its metadata and sidecar, the graph itself unchanged."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import onnx
import pytest

from sinmdm.eval.balance import SMOOTH_CANDIDATES
from sinmdm.export.calibrate import trained_check_cleanup
from sinmdm.runtime import load_model, read_bvh
from sinmdm.runtime.features import build_codec
from sinmdm.runtime.model import DEMO_MODEL

from .conftest import DEMO_CLIP, real_clip, run_cli


def _graph_bytes(path: Path) -> bytes:
    model = onnx.load(str(path))
    del model.metadata_props[:]
    return model.SerializeToString()


@pytest.fixture
def demo_copy(tmp_path: Path) -> Path:
    for source in (DEMO_MODEL, DEMO_MODEL.with_suffix(".json")):
        shutil.copy(source, tmp_path / source.name)
    return tmp_path / DEMO_MODEL.name


@pytest.mark.slow
def test_calibrate_writes_the_measured_defaults(demo_copy: Path):
    result = run_cli("sinmdm", "calibrate", str(demo_copy), "--clip", str(DEMO_CLIP), "--samples", "2",
                     "--threads", "2", "--json", check=True)
    chosen = json.loads(result.stdout)
    tried = [(t["steps"], t["hop"], t["smooth"]) for t in chosen["trials"]]
    assert tried[:5] == [(50, 32, 0), (30, 32, 0), (20, 32, 0), (20, 48, 0), (10, 48, 0)]
    # smoothing is tried on the chosen setting (SMOOTH_CANDIDATES in turn) while its samples shake more than the clip
    smoothing = chosen["trials"][5:]
    assert [(t["steps"], t["hop"]) for t in smoothing] == [(chosen["steps"], chosen["hop"])] * len(smoothing)
    assert [t["smooth"] for t in smoothing] == list(SMOOTH_CANDIDATES[: len(smoothing)])
    raw = next(t for t in chosen["trials"][:5] if (t["steps"], t["hop"]) == (chosen["steps"], chosen["hop"]))
    assert (raw["jitter_ratio"] > 1) == bool(smoothing)
    assert chosen["smooth"] in [0.0] + [t["smooth"] for t in smoothing]
    model = load_model(demo_copy)
    assert model.metadata["sampling_defaults"] == {k: chosen[k] for k in ("steps", "hop", "smooth")}
    assert model.default_steps == chosen["steps"] and model.default_smooth == chosen["smooth"]
    # the demo predates the resting heights: calibration records them from its clip, as training does
    assert load_model(DEMO_MODEL).codec.contact_floors is None
    assert model.codec.contact_floors == build_codec(read_bvh(DEMO_CLIP)).contact_floors
    provenance = model.metadata["provenance"]
    assert provenance["sampling_scores"] == chosen["scores"] and provenance["calibrated"]["samples"] == 2
    # the demo's run checked without the cleanup, so calibration measures without it too, and says so
    assert chosen["cleanup"] is False and provenance["calibrated"]["cleanup"] is False
    stored = next(e.value for e in onnx.load(str(demo_copy)).metadata_props if e.key == "sinmdm")
    assert demo_copy.with_suffix(".json").read_text() == stored  # the sidecar is the same document
    assert _graph_bytes(demo_copy) == _graph_bytes(DEMO_MODEL)  # only the metadata changed


def test_calibration_samples_as_the_run_checked():
    model = load_model(DEMO_MODEL)
    assert trained_check_cleanup(model) is False
    model.metadata["provenance"] = {**model.metadata["provenance"], "train": {"check_cleanup": True}}
    assert trained_check_cleanup(model) is True
    del model.metadata["provenance"]  # a model without provenance: the checks' default
    assert trained_check_cleanup(model) is False


def test_calibrate_refuses_another_clip(demo_copy: Path):
    before = demo_copy.read_bytes()
    result = run_cli("sinmdm", "calibrate", str(demo_copy), "--clip", str(real_clip("Xia_proud.bvh")))
    assert result.returncode == 2 and "is not the clip this model learned" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert demo_copy.read_bytes() == before


def test_calibrate_refuses_one_sample(demo_copy: Path):
    result = run_cli("sinmdm", "calibrate", str(demo_copy), "--clip", str(DEMO_CLIP), "--samples", "1")
    assert result.returncode == 2 and "--samples must be at least 2" in result.stderr


@pytest.mark.parametrize("clip", ["missing.bvh", "."])
def test_calibrate_refuses_an_unreadable_clip(demo_copy: Path, clip: str):
    result = run_cli("sinmdm", "calibrate", str(demo_copy), "--clip", str(demo_copy.parent / clip))
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1
