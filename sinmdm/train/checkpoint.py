"""Durable runs: a run directory holds `config.json` (what was trained on what, and the
sha256 of each weights file), `checkpoint.pt` (everything needed to continue bit-for-bit),
`best.pt` (the watch's best-balanced weights) and `log.jsonl`. Weights files are written
first and the config that names their digests last, all fsynced, so a killed run keeps a
consistent set; a file that does not match its digest is never loaded."""

from __future__ import annotations

import hashlib
import io
import json
from pathlib import Path
from typing import Any, Iterator

import torch

from ..runtime.atomic import OutputSet
from ..runtime.errors import SinMDMError
from .model import ModelConfig
from .presets import TrainConfig

CONFIG = "config.json"
CHECKPOINT = "checkpoint.pt"
BEST = "best.pt"  # the best-balanced check's weights, beside checkpoint.pt
LOG = "log.jsonl"
CHECKSUMS = "checksums"  # config key: {file name: sha256}
RUN_FORMAT = 1
STAGE_PREFIX = "norm-"  # the folder of a run's fallback stage, inside the run
SCORE_KEYS = ("coverage", "global_diversity", "local_diversity", "balance", "jitter_ratio", "check_seconds")

NUMBER = (int, float)
# What every reader of a config relies on: key -> the JSON type(s) it must have.
REQUIRED = {"clip": dict, "codec": dict, "model": dict, "train": dict, "schedule": dict, "seed": int, "window": int,
            "receptive_field": int, "parameters": int, "step": int, "steps": int, "finished": bool, "device": str,
            "elapsed_seconds": NUMBER}
OPTIONAL = {"loss": NUMBER, "watch": dict, "sampling": dict, "stage": dict, "stages": list, "start_position": list, "heading_frame": dict, "root_frame": dict,
            CHECKSUMS: dict}
CLIP = {"name": str, "sha256": str, "frames": int}
WATCH = {"best_step": int, "checks": int}
SAMPLING = {"steps": int, "hop": int, "scores": dict}
STAGE = {"dir": str, "norm": str, "steps": int, "from_step": int, "chosen": bool}


def save_run(run_dir: Path, config: dict, state: dict[str, Any], best: dict | None = None) -> dict[str, str]:
    """Write the checkpoint (and new best weights) first, then the config that names their
    digests; returns the digests the config now records."""
    files = {CHECKPOINT: _serialized(state)}
    if best is not None:
        files[BEST] = _serialized(best)
    checksums = {**(config.get(CHECKSUMS) or {}), **{name: hashlib.sha256(data).hexdigest() for name, data in files.items()}}
    with OutputSet(run_dir, [*files, CONFIG], force=True, estimate_bytes=sum(map(len, files.values()))) as out:
        for name, data in files.items():
            out.write_bytes(name, data)
        out.write_text(CONFIG, json.dumps({**config, CHECKSUMS: checksums}, indent=2) + "\n")
        out.commit()
    return checksums


def _serialized(value: Any) -> bytes:
    buffer = io.BytesIO()
    torch.save(value, buffer)
    return buffer.getvalue()


def load_config(run_dir: Path) -> dict:
    path = Path(run_dir) / CONFIG
    if not path.is_file():
        raise SinMDMError(f"{run_dir} is not a training run: no {CONFIG}")
    try:
        config = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        raise SinMDMError(f"{path} is corrupted: {exc}") from None
    if not isinstance(config, dict) or config.get("run_format") != RUN_FORMAT:
        raise SinMDMError(f"{path} is not a run config of this version (run_format {RUN_FORMAT})")
    _check_config(config, path)
    return config


def _check_config(config: dict, path: Path) -> None:
    """Refuse a damaged config before anything reads it: the keys, their types, the
    nested records that `info` and `export` read, and the model and training settings."""
    _check_fields(config, REQUIRED, path, "")
    _check_fields(config, OPTIONAL, path, "", optional=True)
    _check_fields(config["clip"], CLIP, path, "clip.")
    stages = [("stage", config.get("stage"))] + [(f"stages[{i}]", s) for i, s in enumerate(config.get("stages") or [])]
    for key, fields in (("watch", WATCH), ("sampling", SAMPLING)):
        if config.get(key) is not None:
            _check_fields(config[key], fields, path, f"{key}.")
    for key, stage in stages:
        if stage is None:
            continue
        if not isinstance(stage, dict):
            raise SinMDMError(f"{path}: {key} is not a record")
        _check_fields(stage, STAGE, path, f"{key}.")
        if not stage["dir"].startswith(STAGE_PREFIX) or Path(stage["dir"]).name != stage["dir"]:
            raise SinMDMError(f"{path}: {key}.dir '{stage['dir']}' is not a stage folder of this run")
    for key, scores in [("watch.best", (config.get("watch") or {}).get("best"))] + [(f"{k}.best", (s or {}).get("best")) for k, s in stages]:
        if scores is not None:
            _check_scores(scores, SCORE_KEYS, path, key)
    if config.get("sampling") is not None:
        _check_scores(config["sampling"]["scores"], SCORE_KEYS[:2], path, "sampling.scores")
    try:
        ModelConfig.from_dict(config["model"])
        if not isinstance(TrainConfig.from_dict(config["train"]).preset, str):
            raise TypeError("train.preset must be a string")
    except (TypeError, ValueError) as exc:
        raise SinMDMError(f"{path}: invalid model or training settings ({exc})") from None


def _check_fields(record: Any, fields: dict, path: Path, prefix: str, optional: bool = False) -> None:
    if not isinstance(record, dict):
        raise SinMDMError(f"{path}: '{prefix.rstrip('.')}' must be a JSON object")
    for key, kind in fields.items():
        value = record.get(key)
        if value is None and optional:
            continue
        if key not in record:
            raise SinMDMError(f"{path}: '{prefix}{key}' is missing")
        if not isinstance(value, kind) or (kind is int and isinstance(value, bool)):
            raise SinMDMError(f"{path}: '{prefix}{key}' has the wrong type ({type(value).__name__})")


def _check_scores(scores: Any, keys: tuple[str, ...], path: Path, where: str) -> None:
    _check_fields(scores, dict.fromkeys(keys, NUMBER), path, f"{where}.")


def load_state(run_dir: Path) -> dict[str, Any]:
    """checkpoint.pt, verified against the run's config and checked for non-finite weights."""
    state = _load_verified(Path(run_dir), CHECKPOINT)
    if "model" not in state or "step" not in state:
        raise SinMDMError(f"checkpoint {Path(run_dir) / CHECKPOINT} is incomplete")
    for key in ("model", "ema"):
        if state.get(key) is not None:
            require_finite(state[key], Path(run_dir) / CHECKPOINT)
    return state


def load_best(run_dir: Path) -> dict:
    """best.pt, verified like the checkpoint."""
    best = _load_verified(Path(run_dir), BEST)
    if "weights" not in best or "step" not in best:
        raise SinMDMError(f"{Path(run_dir) / BEST} is incomplete")
    require_finite(best["weights"], Path(run_dir) / BEST)
    return best


def _load_verified(run_dir: Path, name: str) -> dict:
    path = run_dir / name
    if not path.is_file():
        raise SinMDMError(f"{run_dir} has no {name}")
    checksums = load_config(run_dir).get(CHECKSUMS)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise SinMDMError(f"cannot read {path}: {exc.strerror}") from None
    # runs saved before checksums existed have none to check
    if checksums is not None and checksums.get(name) != hashlib.sha256(data).hexdigest():
        raise SinMDMError(f"{path} is corrupted: it does not match the sha256 in {CONFIG} (damaged, or from another run)")
    try:
        loaded = torch.load(io.BytesIO(data), map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many types for a damaged file
        raise SinMDMError(f"{path} is corrupted or unreadable ({type(exc).__name__})") from None
    if not isinstance(loaded, dict):
        raise SinMDMError(f"{path} is incomplete")
    return loaded


def nonfinite_tensor(weights: dict[str, Any]) -> str | None:
    """The name of the first floating-point tensor holding NaN or infinity, else None."""
    for name, value in weights.items():
        if isinstance(value, torch.Tensor) and value.is_floating_point() and not torch.isfinite(value).all():
            return name
    return None


def require_finite(weights: Any, path: Path) -> None:
    if not isinstance(weights, dict):
        raise SinMDMError(f"{path} is incomplete")
    name = nonfinite_tensor(weights)
    if name is not None:
        raise SinMDMError(f"{path} holds non-finite weights ({name}): the run diverged or the file is damaged")


def log_records(run_dir: Path) -> Iterator[tuple[str, dict]]:
    """The run's log lines that are JSON objects, with their text; anything else (a line cut
    by a kill, invalid UTF-8, another JSON type) is skipped."""
    path = Path(run_dir) / LOG
    if not path.is_file():
        return
    for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
        try:
            record = json.loads(line)
        except (json.JSONDecodeError, RecursionError):
            continue
        if isinstance(record, dict) and isinstance(record.get("step"), int):
            yield line, record


def read_log(run_dir: Path) -> list[dict]:
    return [record for _, record in log_records(run_dir)]


def check_records(run_dir: Path) -> list[dict]:
    """The log's quality-check records whose scores are complete."""
    return [r for r in read_log(run_dir) if isinstance(r.get("check"), dict)
            and all(isinstance(r["check"].get(k), (int, float)) for k in SCORE_KEYS)]
