"""`sinmdm eval`: score generated BVH motions against their reference clip (numpy only, no torch)."""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer
from rich.console import Console
from rich.table import Table

from .common import print_json

# (key, label, higher is better, the paper's SinMDM row on the ten-clip Mixamo benchmark)
METRICS = (
    ("coverage", "coverage %", True, 94.3),
    ("global_diversity", "global diversity", True, 1.42),
    ("local_diversity", "local diversity", True, 1.00),
    ("inter_diversity", "inter diversity", True, 0.13),
    ("intra_diversity_diff", "intra diversity diff", False, 0.03),
)


def eval_command(
    reference: Path = typer.Argument(..., help="The clip the model learned from (BVH)."),
    samples: Optional[List[Path]] = typer.Argument(None, help="Generated motions (BVH), any lengths."),
    preset: str = typer.Option(
        "default", "--preset",
        help="default: every rotated joint, detected contacts, slerp to 30 fps. "
        "mixamo24: the paper's 24 Mixamo joints, toe contacts at 0.018 m/frame, frames dropped to 30 fps.",
    ),
    seed: int = typer.Option(0, "--seed", help="Seed of the random windows of intra diversity."),
    source_fps: Optional[float] = typer.Option(
        None, "--source-fps", help="Override the declared frame rate of every file (reference and samples)."
    ),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
) -> None:
    """Score samples against their reference with the paper's metrics (coverage, diversity)."""
    from ..eval.motion_features import evaluate_files

    result = evaluate_files(reference, list(samples or []), preset=preset, seed=seed, source_fps=source_fps)
    if as_json:
        print_json(result)
        return
    console = Console()
    console.print(_table(result, reference))
    _print_plausibility(console, result.get("plausibility"), samples or [])


def _table(result: dict, reference: Path) -> Table:
    frames = result["sample_frames"]
    lengths = f"{min(frames)}" if min(frames) == max(frames) else f"{min(frames)}-{max(frames)}"
    table = Table(
        title=f"{result['samples']} sample(s) of {lengths} frames vs {reference.name} ({result['reference_frames']} frames)",
        caption=f"preset {result['preset']}, {result['feature_width']} features per frame at {result['fps']:g} fps",
    )
    table.add_column("metric")
    table.add_column("better", justify="center")
    table.add_column("value", justify="right")
    table.add_column("paper SinMDM (Mixamo)", justify="right", style="dim")
    for key, label, higher, paper in METRICS:
        table.add_row(label, "↑ higher" if higher else "↓ lower", f"{result[key]:.2f}", f"{paper:.2f}")
    return table


PLAUSIBILITY = (
    ("root_step_max_ratio", "largest root step / clip's", None),
    ("speed_distance_m_s", "root speed distance (m/s)", None),
    ("pace_m_s", "pace: travel per second (m/s)", "clip_pace_m_s"),
    ("pace_distance_m_s", "pace distance (m/s)", None),
    ("backward_share", "frames walking backwards", "clip_backward_share"),
    ("turning_deg_s", "turning (deg/s, + left)", "clip_turning_deg_s"),
    ("turning_distance_deg_s", "turning distance (deg/s)", None),
    ("fastest_turn_deg_s", "fastest turn (deg/s, worst sample)", "clip_fastest_turn_deg_s"),
    ("planted_share", "frames with feet planted", "clip_planted_share"),
    ("foot_lift_cm", "how high the feet lift (cm)", "clip_foot_lift_cm"),
    ("foot_skating_cm_s", "foot skating (cm/s)", "clip_foot_skating_cm_s"),
    ("foot_bob_cm_s", "planted feet bobbing (cm/s)", "clip_foot_bob_cm_s"),
    ("penetration_cm", "floor penetration (cm)", None),
    ("jitter_ratio", "jerk / clip's", None),
)


def _print_plausibility(console: Console, plausible: dict | None, samples: list[Path]) -> None:
    if not plausible or not plausible.get("aggregate"):
        return
    aggregate = plausible["aggregate"]
    table = Table(title="what an animator sees (plausibility)")
    table.add_column("metric")
    table.add_column("samples", justify="right")
    table.add_column("clip", justify="right", style="dim")
    for key, label, clip_key in PLAUSIBILITY:
        clip = f"{aggregate[clip_key]:.2f}" if clip_key else ("1.00" if key.endswith("_ratio") else "0.00")
        if key == "backward_share":
            clip += f" (halves up to {aggregate['clip_backward_half_max']:.2f})"
        if key == "turning_distance_deg_s":
            clip += f" (halves {aggregate['clip_turning_halves_deg_s']:.2f})"
        if key == "pace_distance_m_s":
            clip += f" (halves {aggregate['clip_pace_halves_m_s']:.2f})"
        table.add_row(label, f"{aggregate[key]:.2f}", clip)
    console.print(table)
    for path, row in zip(samples, plausible["samples"]):
        console.print(f"{Path(path).name}: {row['verdict']}")


def register(app: typer.Typer) -> None:
    app.command("eval")(eval_command)
