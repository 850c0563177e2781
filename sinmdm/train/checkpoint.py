"""Durable runs: a run directory holds `config.json` (what was trained on what),
`checkpoint.pt` (everything needed to continue bit-for-bit) and `log.jsonl`.
Both files are replaced atomically, so a killed run always has a consistent pair."""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any

import torch

from ..runtime.atomic import atomic_path, write_text_atomic
from ..runtime.errors import SinMDMError

CONFIG = "config.json"
CHECKPOINT = "checkpoint.pt"
LOG = "log.jsonl"
RUN_FORMAT = 1


def file_sha256(path: str | os.PathLike) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def save_run(run_dir: Path, config: dict, state: dict[str, Any]) -> None:
    """Write the checkpoint first, then the config that describes it."""
    with atomic_path(run_dir / CHECKPOINT) as tmp:
        torch.save(state, tmp)
    write_text_atomic(run_dir / CONFIG, json.dumps(config, indent=2) + "\n")


def load_config(run_dir: Path) -> dict:
    path = Path(run_dir) / CONFIG
    if not path.is_file():
        raise SinMDMError(f"{run_dir} is not a training run: no {CONFIG}")
    try:
        config = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise SinMDMError(f"{path} is corrupted: {exc}") from None
    if not isinstance(config, dict) or config.get("run_format") != RUN_FORMAT:
        raise SinMDMError(f"{path} is not a run config of this version (run_format {RUN_FORMAT})")
    return config


def load_state(run_dir: Path) -> dict[str, Any]:
    path = Path(run_dir) / CHECKPOINT
    if not path.is_file():
        raise SinMDMError(f"{run_dir} has no checkpoint ({CHECKPOINT})")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many types for a damaged file
        raise SinMDMError(f"checkpoint {path} is corrupted or unreadable ({type(exc).__name__})") from None
    if not isinstance(state, dict) or "model" not in state or "step" not in state:
        raise SinMDMError(f"checkpoint {path} is incomplete")
    return state


def read_log(run_dir: Path) -> list[dict]:
    """The run's log records (lines that are not JSON objects, e.g. cut by a kill, are skipped)."""
    path = Path(run_dir) / LOG
    if not path.is_file():
        return []
    records = []
    for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
        try:
            record = json.loads(line)
        except json.JSONDecodeError:
            continue
        if isinstance(record, dict):
            records.append(record)
    return records
