"""Render bench/results/*.json as the markdown tables of BENCHMARKS.md.

    python bench/report.py > /tmp/tables.md
    python bench/report.py --update BENCHMARKS.md   # refresh the tables in place
"""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"
PAPER_ROWS = [  # name, steps, samples, coverage, global, local, inter, intra diff
    ("paper: SinMDM, Mixamo mean (10 clips)", 1000, 20, 94.3, 1.42, 1.00, 0.13, 0.03),
    ("paper: SinMDM, Gangnam style", 1000, 20, 98.1, 1.55, 1.12, None, None),
    ("paper: GANimator, Mixamo mean", "-", 20, 94.3, 1.24, 1.17, 0.09, 0.13),
    ("notes: CPU pilot (Mixamo dance), 64-frame windows", 50, 10, 87.9, 1.13, 0.87, 0.12, None),
]


def header(*cells: str) -> list[str]:
    return ["| " + " | ".join(cells) + " |", "|" + "---|" * len(cells)]


METRIC_CELLS = ("coverage %", "global div", "local div", "inter div", "intra div diff")


def results(name: str):
    """The parsed bench/results/NAME.json, or None before that benchmark has run."""
    path = RESULTS / f"{name}.json"
    return json.loads(path.read_text()) if path.exists() else None


def fmt(value, digits=2) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def _metric_cells(row: dict) -> str:
    return (f"{fmt(row['coverage'], 1)} | {fmt(row['global_diversity'])} | {fmt(row['local_diversity'])} "
            f"| {fmt(row['inter_diversity'])} | {fmt(row['intra_diversity_diff'])}")


def quality_table() -> str:
    data = results("quality")
    if data is None:
        return "(no quality results yet)\n"
    lines = [
        "| clip | preset | train it | train time | eval protocol | steps | samples | coverage % | global div | local div | inter div | intra div diff | s per sample |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for entry in data:
        for row in entry["rows"]:
            lines.append(
                f"| {entry['clip']} | {entry['preset']} | {entry['train_steps']} | {entry['train_wall_seconds'] / 60:.1f} min "
                f"| {row['eval_preset']} | {row['steps']} | {row['samples']} x {row['frames']} f | {_metric_cells(row)} "
                f"| {row['sampling_seconds'] / row['samples']:.2f} |"
            )
    for name, steps, samples, cov, glob, local, inter, intra in PAPER_ROWS:
        lines.append(f"| {name} | | | | | {steps} | {samples} | {fmt(cov, 1)} | {fmt(glob)} | {fmt(local)} | {fmt(inter)} | {fmt(intra)} | |")
    return "\n".join(lines) + "\n"


def speed_table() -> str:
    data = results("sampling_speed")
    if data is None:
        return "(no sampling-speed results yet)\n"
    lines = ["| measurement | frames | steps | result |", "|---|---|---|---|"]
    for row in data["rows"]:
        kind = row["kind"]
        if kind in ("steps", "length"):
            result = f"{row['seconds_per_sample']:.3f} s per sample"
        elif kind == "crowd":
            result = f"{row['seconds_per_sample']:.3f} s per sample (crowd of {row['count']} in one batch)"
        elif kind == "backend":
            result = f"onnxruntime {row['onnxruntime']:.3f} s, torch eager {row['torch_eager']:.3f} s ({row['speedup']:.2f}x)"
        else:
            result = f"peak RSS {row['peak_rss_mb']:.0f} MB, {row['wall_seconds']:.0f} s wall (whole process)"
        lines.append(f"| {kind} | {row['frames']} | {row['steps']} | {result} |")
    return "\n".join(lines) + "\n"


def _duration(seconds: float) -> str:
    return f"{seconds / 60:.0f} min" if seconds < 3 * 3600 else f"{seconds / 3600:.0f} h"


def train_speed_table() -> str:
    data = results("train_speed")
    if data is None:
        return "(no training-speed results yet)\n"
    lines = ["| clip | preset | features | frames per example | bf16 | compiled | first step s | s per iteration | projected run of the preset's steps |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in data["rows"]:
        lines.append(f"| {r['clip']} | {r['preset']} | {r['features']} | {r['window']} | {r['bf16']} | {r['compiled']} "
                     f"| {r['first_step_seconds']:.1f} | {r['seconds_per_iteration']:.3f} "
                     f"| {_duration(r['full_run_hours'] * 3600)} ({r['steps']} it) |")
    return "\n".join(lines) + "\n"


def steps_table() -> str:
    data = results("steps_compare")
    if data is None:
        return "(no step comparison yet)\n"
    lines = header("clip", "steps", "samples", *METRIC_CELLS, "s per sample")
    for entry in data:
        for row in entry["rows"]:
            lines.append(f"| {entry['clip']} | {row['steps']} | {row['samples']} x {row['frames']} f | {_metric_cells(row)} "
                         f"| {row['sampling_seconds'] / row['samples']:.1f} |")
    return "\n".join(lines) + "\n"


def recipe_table() -> str:
    """The cpu recipe's ablations beside the quality run of the unchanged preset."""
    entries = results("recipe")
    if entries is None:
        return "(no recipe ablations yet)\n"
    clips = {e["clip"] for e in entries}
    lines = header("clip", "variant", "train it", *METRIC_CELLS)
    for entry in results("quality") or []:
        if entry["clip"] in clips and entry["preset"] == "cpu":
            lines.append(f"| {entry['clip']} | cpu preset as shipped | {entry['train_steps']} | {_metric_cells(entry['rows'][0])} |")
    for entry in entries:
        variant = f"{entry['variant']} (`{' '.join(entry['overrides'])}`)"
        lines.append(f"| {entry['clip']} | {variant} | {entry['train_steps']} | {_metric_cells(entry['rows'][0])} |")
    return "\n".join(lines) + "\n"


def fast_sampling_table() -> str:
    """Fewer steps and sparser windows on the quality runs' models, 20 samples each."""
    entries = results("fast_sampling")
    if entries is None:
        return "(no fast-sampling grid yet)\n"
    lines = header("clip", "sampler", "steps", "hop", "samples", *METRIC_CELLS)
    clips = {e["clip"] for e in entries}
    for entry in results("quality") or []:
        if entry["clip"] in clips:
            row = entry["rows"][0]
            lines.append(f"| {entry['clip']} | ddpm (default) | {row['steps']} | {entry['window'] // 2} "
                         f"| {row['samples']} x {row['frames']} f | {_metric_cells(row)} |")
    for entry in entries:
        for row in entry["rows"]:
            lines.append(f"| {entry['clip']} | {row['sampler']} | {row['steps']} | {row['hop']} "
                         f"| {row['samples']} x {row['frames']} f | {_metric_cells(row)} |")
    return "\n".join(lines) + "\n"


def layouts_table(name: str = "layouts") -> str:
    """Every shared clip and derived layout, short-trained: the paper's metrics beside
    the plausibility aggregate, per sampler variant (and seed set)."""
    entries = results(name)
    if entries is None:
        return "(no layouts results yet)\n"
    lines = header("case", "sampler", "coverage %", "global div", "local div", "largest root step (x clip)",
                   "backward % (clip)", "foot skating cm/s (clip)", "in floor cm (% frames)", "jitter (x clip)",
                   "plausible")
    for entry in entries:
        for key, v in entry["variants"].items():
            a = (v.get("plausibility") or {}).get("aggregate")
            if not a:
                continue
            lines.append(
                f"| {entry['tag']} | {key} | {fmt(v['coverage'], 1)} | {fmt(v['global_diversity'])} | {fmt(v['local_diversity'])} "
                f"| {fmt(a['root_step_max_ratio'])} | {fmt(100 * a['backward_share'], 0)} ({_clip_backward(a)}) "
                f"| {fmt(a['foot_skating_cm_s'], 1)} ({fmt(a['clip_foot_skating_cm_s'], 1)}) "
                f"| {fmt(a['penetration_cm'], 1)} ({fmt(100 * a['penetration_share'], 0)}) | {fmt(a['jitter_ratio'], 1)} "
                f"| {entry['samples'] - a['implausible']}/{entry['samples']} |")
    return "\n".join(lines) + "\n"


def _clip_backward(aggregate: dict) -> str:
    """The clip's backward share, and the most any half of it has where that was measured."""
    share = fmt(100 * aggregate["clip_backward_share"], 0)
    half = aggregate.get("clip_backward_half_max")
    return share if half is None else f"{share}, halves <= {fmt(100 * half, 0)}"


def watched_table(name: str = "watched", jitter: bool = False) -> str:
    """The watched `cpu` recipe per clip beside the previous preset (quality.json) and the paper;
    `jitter`: also the jitter column (results since the plausibility metrics had it)."""
    entries = results(name)
    if entries is None:
        return "(no watched results yet)\n"
    old = {e["clip"]: e for e in (results("quality") or []) if e.get("preset") == "cpu"}
    lines = header("clip", "recipe", "train it (kept)", "train wall", "sampler", "steps / hop", "coverage %",
                   "global div", "local div", "foot skating cm/s (clip)", "largest root step (x clip)",
                   *(["jitter (x clip)"] if jitter else []), "plausible")
    blank = "| " * (4 if jitter else 3)
    for entry in entries:
        previous = old.get(entry["clip"]) if entry.get("layout") == "as shared" and not entry.get("seed") else None
        if previous:
            for row in previous["rows"]:
                if row.get("steps") == 50 and row.get("variant", "faithful") in ("faithful", None):
                    lines.append(f"| {entry['tag']} | previous `cpu` (3000 it) | {previous['train_steps']} | "
                                 f"{_duration(previous['train_wall_seconds'])} | faithful | 50 / 32 | {fmt(row['coverage'], 1)} | "
                                 f"{fmt(row['global_diversity'])} | {fmt(row['local_diversity'])} {blank}|")
                    break
        for row in entry["rows"]:
            a = row.get("plausibility") or {}
            lines.append(
                f"| {entry['tag']} | watched `cpu` | {entry['train_steps']} ({entry['kept_step']}) | "
                f"{_duration(entry['train_wall_seconds'])} | {row['variant']} | {row['steps']} / {row['hop']} | "
                f"{fmt(row['coverage'], 1)} | {fmt(row['global_diversity'])} | {fmt(row['local_diversity'])} | "
                f"{fmt(a.get('foot_skating_cm_s'), 1)} ({fmt(a.get('clip_foot_skating_cm_s'), 1)}) | "
                f"{fmt(a.get('root_step_max_ratio'))} | " + (f"{fmt(a.get('jitter_ratio'), 1)} | " if jitter else "")
                + f"{row['samples'] - a.get('implausible', 0)}/{row['samples']} |")
    for paper, steps, _, c, g, l, _, _ in PAPER_ROWS:
        if paper.startswith("paper: SinMDM"):
            lines.append(f"| {paper} | | | | | {steps} | {fmt(c, 1)} | {fmt(g)} | {fmt(l)} {blank}|")
    return "\n".join(lines) + "\n"


def root_frame_table(date: str = "2026-12-06") -> str:
    """The watched `cpu` recipe per clip in the world frame (the paper's features) and in the
    heading frame (`--root-frame heading`), default sampler: the paper's metrics beside turning
    and the plausibility verdicts (bench/watched.py, results `watched_{world,heading}_{date}`; a clip
    not rerun in the world frame shows the compiled benchmark's run of the same recipe)."""
    world, heading = results(f"watched_world_{date}") or [], results(f"watched_heading_{date}") or []
    measured = {e["tag"] for e in world}
    earlier = [e for e in results(f"watched_compiled_{date}") or [] if e["tag"] not in measured]
    arms = [("world", world), ("world (earlier run, no turning metric)", earlier), ("heading", heading)]
    if not world and not heading:
        return "(no root frame results yet)\n"
    lines = header("clip", "root frame", "train wall", "coverage %", "global div", "local div",
                   "turning deg/s (clip)", "turning distance deg/s (clip halves)", "largest root step (x clip)",
                   "jitter (x clip)", "plausible", "verdicts")
    tags = [e["tag"] for _, entries in arms for e in entries or []]
    for tag in dict.fromkeys(tags):
        for frame, entries in arms:
            entry = next((e for e in entries or [] if e["tag"] == tag), None)
            row = entry and next((r for r in entry["rows"] if r["variant"] == "default"), None)
            if not row:
                continue
            a = row.get("plausibility") or {}
            verdicts = Counter(v.split(" ")[0].rstrip(":") for v in row.get("verdicts") or [])
            lines.append(
                f"| {tag} | {frame} | {_duration(entry['train_wall_seconds'])} | {fmt(row['coverage'], 1)} "
                f"| {fmt(row['global_diversity'])} | {fmt(row['local_diversity'])} "
                f"| {fmt(a.get('turning_deg_s'), 1)} ({fmt(a.get('clip_turning_deg_s'), 1)}) "
                f"| {fmt(a.get('turning_distance_deg_s'), 1)} ({fmt(a.get('clip_turning_halves_deg_s'), 1)}) "
                f"| {fmt(a.get('root_step_max_ratio'))} | {fmt(a.get('jitter_ratio'), 1)} "
                f"| {row['samples'] - a.get('implausible', 0)}/{row['samples']} "
                f"| {', '.join(f'{k} {v}' for k, v in sorted(verdicts.items()))} |")
    return "\n".join(lines) + "\n"


# The latest run of the `cpu` recipe with checks that sample without the cleanup, per clip tag
# (the walk: the heading frame that `--root-frame auto` picks for it).
WITHOUT_CLEANUP_RUNS = {"Joe_Walk-In-Circle": "watched_heading_2026-12-06",
                        "Joe_Walk-In-Circle-static-root-z-up": "watched_heading_2026-12-06",
                        "Crabnew_Crab-dance-long": "watched_world_2026-12-06"}


def _watch_share(entry: dict) -> str:
    """Seconds the watch took (its checks, then the sampling calibration's trials) and their share
    of the whole `sinmdm train` wall (compilation, both stages, export of the checkpoint included)."""
    calibration = sum(t.get("check_seconds", 0.0) for t in (entry.get("sampling") or {}).get("trials", []))
    seconds = entry["check_seconds"] + calibration
    return f"{seconds:.0f} s: {100 * seconds / entry['train_wall_seconds']:.0f} %"


def as_sampled_table(name: str = "watched_as_sampled_2026-12-07", default: str = "watched_default_2026-12-07") -> str:
    """Per clip, default sampler: the `cpu` recipe's latest run with checks on raw samples, the run with
    checks that sample as `sample` does (cleanup, calibrated smoothing of shaking samples), and the
    default of 2026-12-07 (those checks and the pace term in the balance)."""
    as_sampled, shipped = results(name) or [], results(default) or []
    if not as_sampled and not shipped:
        return "(no as-sampled results yet)\n"
    lines = header("clip", "checks", "kept step (of)", "train wall", "checks + calibration, share of the wall", "coverage %", "global div",
                   "local div", "pace m/s (clip)", "turning distance deg/s (allowed)", "jitter (x clip)", "smoothing",
                   "plausible", "verdicts")
    for tag in dict.fromkeys(e["tag"] for e in [*as_sampled, *shipped]):
        baseline = results(WITHOUT_CLEANUP_RUNS.get(tag, "watched_compiled_2026-12-06")) or []
        arms = [("raw samples", next((e for e in baseline if e["tag"] == tag), None)),
                ("as sampled", next((e for e in as_sampled if e["tag"] == tag), None)),
                ("**as sampled + pace (default)**", next((e for e in shipped if e["tag"] == tag), None))]
        for label, arm in arms:
            row = arm and next((r for r in arm["rows"] if r["variant"] == "default"), None)
            if not row:
                continue
            a = row.get("plausibility") or {}
            allowed = max(10.0, 2 * a["clip_turning_halves_deg_s"]) if "clip_turning_halves_deg_s" in a else None
            verdicts = Counter(v.split(":")[0].split(" ")[0] for v in row.get("verdicts") or [])
            lines.append(
                f"| {tag} | {label} | {arm['kept_step']} ({arm['train_steps']}) | {_duration(arm['train_wall_seconds'])} "
                f"| {_watch_share(arm)} | {fmt(row['coverage'], 1)} "
                f"| {fmt(row['global_diversity'])} | {fmt(row['local_diversity'])} "
                f"| {fmt(a.get('pace_m_s'))} ({fmt(a.get('clip_pace_m_s'))}) "
                f"| {fmt(a.get('turning_distance_deg_s'), 1)} ({fmt(allowed, 1)}) | {fmt(a.get('jitter_ratio'), 1)} "
                f"| {fmt((arm.get('sampling_chosen') or {}).get('smooth'), 0)} "
                f"| {row['samples'] - a.get('implausible', 0)}/{row['samples']} "
                f"| {', '.join(f'{k} {v}' for k, v in sorted(verdicts.items()))} |")
    return "\n".join(lines) + "\n"


# The recipe arms of 2026-12-07: the default run of that day, then each arm (`--train-args` of bench/watched.py).
RECIPE_ARMS = (("default (crop 64, EMA with warm-up, uniform loss)", ["watched_default_2026-12-07"]),
               ("`--crop 96`", ["recipe_crop96_2026-12-07", "recipe_crop96_idle_2026-12-07"]), ("`--ema 0` (raw weights)", ["recipe_noema_2026-12-07"]),
               ("`--loss-weighting min-snr`", ["recipe_minsnr_2026-12-07"]),
               ("`--steps 4800` (tail from 3,360)", ["recipe_crab_long_2026-12-07"]))


def recipe_arms_table() -> str:
    """Per clip, default sampler, 20 samples of twice the clip: the default recipe beside one-override arms."""
    arms = [(label, [e for name in names for e in results(name) or []]) for label, names in RECIPE_ARMS]
    tags = list(dict.fromkeys(e["tag"] for _, entries in arms[1:] for e in entries))
    if not tags:
        return "(no recipe arms yet)\n"
    lines = header("clip", "recipe", "kept step (of)", "train wall", "steps / hop / smoothing", "coverage %", "global div",
                   "local div", "jitter (x clip)", "pace m/s (clip)", "plausible")
    for tag in tags:
        for label, entries in arms:
            entry = next((e for e in entries if e["tag"] == tag), None)
            row = entry and next((r for r in entry["rows"] if r["variant"] == "default"), None)
            if not row:
                continue
            a, chosen = row.get("plausibility") or {}, entry.get("sampling_chosen") or {}
            lines.append(
                f"| {tag} | {label} | {entry['kept_step']} ({entry['train_steps']}) | {_duration(entry['train_wall_seconds'])} "
                f"| {row['steps']} / {row['hop']} / {fmt(chosen.get('smooth'), 0)} | {fmt(row['coverage'], 1)} "
                f"| {fmt(row['global_diversity'])} | {fmt(row['local_diversity'])} | {fmt(a.get('jitter_ratio'), 1)} "
                f"| {fmt(a.get('pace_m_s'))} ({fmt(a.get('clip_pace_m_s'))}) | {row['samples'] - a.get('implausible', 0)}/{row['samples']} |")
    return "\n".join(lines) + "\n"


def crab_sampling_table(name: str = "crab_sampling_grid_2026-12-07") -> str:
    """bench/steps_compare.py on the default crab model: 20 samples per sampling setting."""
    entries = results(name)
    if not entries:
        return "(no sampling grid yet)\n"
    lines = header("steps / hop", "coverage %", "global div", "local div", "sampling s (20 samples)")
    for row in sorted((r for e in entries for r in e["rows"]), key=lambda r: (r["hop"], -r["steps"])):
        lines.append(f"| {row['steps']} / {row['hop']} | {fmt(row['coverage'], 1)} | {fmt(row['global_diversity'])} "
                     f"| {fmt(row['local_diversity'])} | {fmt(row['sampling_seconds'], 0)} |")
    return "\n".join(lines) + "\n"


def coverage_margin_table(name: str = "coverage_margin-2026-12-07") -> str:
    """bench/coverage_margin.py: the paper's coverage taken apart, one row per folder of samples."""
    entries = results(name)
    if not entries:
        return "(no coverage margin results yet)\n"
    lines = header("clip: samples", "coverage %", "rotations only", "at 1.125x / 1.25x the threshold",
                   "labels' share of the matched cost", "moving where the clip is still / still where it moves",
                   "labels still, samples (clip)")
    for e in entries:
        c, k = e["coverage"], e.get("contacts")
        labels = (f"| {fmt(k['share_of_matched_cost'])} | {fmt(100 * k['moving_where_clip_still'], 1)} % / "
                  f"{fmt(100 * k['still_where_clip_moving'], 1)} % | {fmt(100 * k['sample_still_share'], 0)} % "
                  f"({fmt(100 * k['clip_still_share'], 0)} %)") if k else "| - | - | -"
        lines.append(f"| {Path(e['clip']).stem}: {e['samples']} | {fmt(c['paper'], 1)} | {fmt(c['rotations only'], 1)} "
                     f"| {fmt(c['threshold x1.125'], 1)} / {fmt(c['threshold x1.25'], 1)} {labels} |")
    return "\n".join(lines) + "\n"


def in_order_table(name: str = "in_order_2026-12-07") -> str:
    """bench/in_order.py: coverage of samples made of exact copies of the clip in stretches of L
    frames, per clip, and the in-order run length of real samples."""
    entries = results(name)
    if entries is None:
        return "(no in-order results yet)\n"
    lengths = (32, 64, 96, 128, 192, 256)  # bench/in_order.py STRETCHES; a clip shorter than one shows the whole clip
    lines = header("clip (frames at 30 fps)", *[f"stretches of {n}" for n in lengths], "the whole clip in order",
                   "samples' in-order runs, frames")
    for e in entries:
        by_length = {c["stretch"]: c for c in e["copied"]}
        cells = [(f"{fmt(by_length[n]['coverage'], 1)} ({' / '.join(fmt(v, 1) for v in by_length[n]['coverage_per_seed'])})"
                  if n in by_length and n < e["frames"] else "") for n in lengths]
        whole = next(c for c in e["copied"] if c["stretch"] == e["frames"])
        runs = "; ".join(f"{fmt(r['in_order_run_frames'], 1)} ({Path(r['samples']).name})" for r in e["samples"])
        lines.append(f"| {e['clip']} ({e['frames']}) | {' | '.join(cells)} | {fmt(whole['coverage'], 1)} | {runs} |")
    return "\n".join(lines) + "\n"


def turning_table(name: str = "turning_2026-12-06") -> str:
    """bench/turning.py: turning within one window and at the joins of windows, per model."""
    entries = results(name)
    if entries is None:
        return "(no turning results yet)\n"
    lines = header("model", "frames", "hop", "turning deg/s (clip)", "turning distance deg/s",
                   "fastest turn per sample, deg/s (clip's)", "verdicts")
    for entry in entries:
        for r in entry["rows"]:
            verdicts = Counter(v.split(" ")[0].rstrip(":") for v in r["verdicts"])
            lines.append(f"| {entry['tag']} | {r['frames']} | {r['hop'] or 'one window'} | {fmt(r['turning_deg_s'], 1)} "
                         f"({fmt(r['clip_turning_deg_s'], 1)}) | {fmt(r['turning_distance_deg_s'], 1)} "
                         f"| {', '.join(str(v) for v in r['fastest_turn_deg_s'])} ({fmt(r['clip_fastest_turn_deg_s'], 0)}) "
                         f"| {', '.join(f'{k} {v}' for k, v in sorted(verdicts.items()))} |")
    return "\n".join(lines) + "\n"


def watched_curve_table(name: str = "watched", jitter: bool = False) -> str:
    """The quality curve of every watched run: the scores at each check; `jitter`: also each
    check's jitter, and `s` where the check was scored smoothed (checks as sampled)."""
    entries = results(name)
    if entries is None:
        return "(no watched results yet)\n"
    lines = header("clip", "step: coverage % / global div / jitter (balance); s = smoothed, * = kept" if jitter
                   else "step: coverage % / global div (balance); * = kept")
    for entry in entries:
        cells, stage = [], None
        for c in entry["checks"]:
            if c.get("stage") != stage:  # the second stage starts: mark it
                stage = c.get("stage")
                cells.append(f"**then {stage}:**")
            shake = f" / {fmt(c['jitter_ratio'], 1)}x{' s' if c.get('smooth') else ''}" if jitter else ""
            cells.append(f"{c['step']}: {fmt(c['coverage'], 0)} / {fmt(c['global_diversity'])}{shake} ({fmt(c['balance'])})"
                         + ("*" if c["step"] == entry["kept_step"] else ""))
        lines.append(f"| {entry['tag']} | {'; '.join(cells).replace(':**;', ':**')} |")
    return "\n".join(lines) + "\n"


SMOOTHING_CLIPS = ("walk", "idle", "xia_normal", "elephant", "crab", "demo")


def _clip_entries(name: str, date: str):
    """(clip, entry) of each SMOOTHING_CLIPS result `{name}_{clip}_{date}` that exists."""
    for clip in SMOOTHING_CLIPS:
        entry = results(f"{name}_{clip}_{date}")
        if entry is not None:
            yield clip, entry


def _per_seed(rows: list[dict]):
    """cell(key, digits, scale): the rows' values (one per seed set) as "a / b"."""
    def cell(key: str, digits: int = 2, scale: float = 1.0) -> str:
        return " / ".join(fmt(None if r.get(key) is None else r[key] * scale, digits) for r in rows)
    return cell


def _plausible_cells(rows: list[dict]) -> str:
    """The "plausible of 8" and "verdicts" cells of the rows (one per seed set of 8 samples)."""
    verdicts = Counter()
    for r in rows:
        verdicts.update(r.get("verdicts") or {})
    return (f"{' / '.join(str(8 - r['implausible']) for r in rows)} "
            f"| {', '.join(f'{k} {v}' for k, v in sorted(verdicts.items()))}")


def smoothing_table(date: str = "2026-12-06") -> str:
    """bench/jitter_sources.py per clip: each smoothing sigma, both seed sets (seed 0 / 1000)."""
    lines = header("model (clip)", "sigma (frames)", "coverage %", "global div", "local div", "jitter (x clip)",
                   "skating cm/s", "in floor cm (% frames)", "largest root step (x clip)", "plausible of 8", "verdicts")
    entries = list(_clip_entries("smoothing", date))
    for clip, entry in entries:
        label = f"{clip} ({entry['clip']}, {entry['default_steps']} steps)"
        for sigma in sorted({r["sigma_frames"] for r in entry["smoothing"]}):
            rows = [r for r in entry["smoothing"] if r["sigma_frames"] == sigma]
            cell = _per_seed(rows)
            lines.append(
                f"| {label} | {sigma:g} | {cell('coverage', 1)} | {cell('global_diversity', 3)} | {cell('local_diversity', 3)} "
                f"| {cell('jitter_ratio')} | {cell('foot_skating_cm_s')} | {cell('penetration_cm', 1)} ({cell('penetration_share', 0, 100)}) "
                f"| {cell('root_step_max_ratio')} | {_plausible_cells(rows)} |")
            label = ""
    return "\n".join(lines) + "\n" if entries else "(no smoothing results yet)\n"


def contact_floors_table(date: str = "2026-12-06") -> str:
    """bench/contact_floors.py per clip: pins as sampled against lifted, both seed sets (seed 0 / 1000)."""
    lines = header("model (clip)", "pins", "coverage %", "global div", "local div", "in floor cm (% frames)",
                   "skating cm/s", "bobbing cm/s", "jitter (x clip)", "plausible of 8", "verdicts")
    entries = list(_clip_entries("contact_floors", date))
    for clip, entry in entries:
        label = f"{clip} ({entry['clip']})"
        for arm in ("as sampled", "lifted"):
            rows = [r for r in entry["rows"] if r["pins"] == arm]
            cell = _per_seed(rows)
            lines.append(
                f"| {label} | {arm} | {cell('coverage', 1)} | {cell('global_diversity', 3)} | {cell('local_diversity', 3)} "
                f"| {cell('penetration_cm', 1)} ({cell('penetration_share', 0, 100)}) | {cell('foot_skating_cm_s')} "
                f"| {cell('foot_bob_cm_s')} | {cell('jitter_ratio')} | {_plausible_cells(rows)} |")
            label = ""
    return "\n".join(lines) + "\n" if entries else "(no contact floor results yet)\n"


TABLES = {"WATCHED_TABLE": watched_table, "WATCHED_1206_TABLE": lambda: watched_table("watched_2026-12-06", jitter=True),
          "WATCHED_COMPILED_TABLE": lambda: watched_table("watched_compiled_2026-12-06", jitter=True),
          "ROOT_FRAME_TABLE": root_frame_table, "TURNING_TABLE": turning_table,
          "AS_SAMPLED_TABLE": as_sampled_table, "AS_SAMPLED_CURVE_TABLE": lambda: watched_curve_table("watched_default_2026-12-07", jitter=True),
          "IN_ORDER_TABLE": in_order_table, "COVERAGE_MARGIN_TABLE": coverage_margin_table, "RECIPE_ARMS_TABLE": recipe_arms_table,
          "CRAB_LONG_CURVE_TABLE": lambda: watched_curve_table("recipe_crab_long_2026-12-07", jitter=True), "CRAB_SAMPLING_TABLE": crab_sampling_table,
          "WATCHED_COMPILED_4000_TABLE": lambda: watched_table("watched_compiled_4000_2026-12-06", jitter=True), "WATCHED_CURVE_TABLE": watched_curve_table, "LAYOUTS_TABLE": layouts_table,
          "LAYOUTS_1205_TABLE": lambda: layouts_table("layouts_2026-12-05"),
          "LAYOUTS_1206_TABLE": lambda: layouts_table("layouts_2026-12-06"), "SMOOTHING_TABLE": smoothing_table, "CONTACT_FLOORS_TABLE": contact_floors_table,
          "LAYOUTS_FLOORS_TABLE": lambda: layouts_table("layouts_floors_2026-12-06"), "QUALITY_TABLE": quality_table, "SPEED_TABLE": speed_table, "TRAIN_SPEED_TABLE": train_speed_table,
          "STEPS_TABLE": steps_table, "RECIPE_TABLE": recipe_table, "FAST_SAMPLING_TABLE": fast_sampling_table}


def update(path: Path) -> None:
    """Replace the table under each `<!-- NAME -->` marker of a markdown file."""
    lines, out = path.read_text().splitlines(), []
    i = 0
    while i < len(lines):
        line = lines[i]
        out.append(line)
        i += 1
        name = line.removeprefix("<!-- ").removesuffix(" -->")
        if line.startswith("<!-- ") and name in TABLES:
            while i < len(lines) and lines[i].startswith("|"):
                i += 1
            out.extend(TABLES[name]().rstrip("\n").splitlines())
    path.write_text("\n".join(out) + "\n")


if __name__ == "__main__":
    import sys

    if sys.argv[1:2] == ["--update"]:
        update(Path(sys.argv[2]))
    else:
        for name, table in TABLES.items():
            print(f"<!-- {name} -->")
            print(table())
