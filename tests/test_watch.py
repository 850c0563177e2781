"""The watched training run: the balance, the stop rule, a real run that keeps its
best check, and an export that carries the choice to `sinmdm-run sample`."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sinmdm.eval.balance import SMOOTH_CANDIDATES, CheckSettings, ClipScorer, balance, in_band
from sinmdm.eval.metrics import harmonic_mean
from sinmdm.runtime import load_model, read_bvh
from sinmdm.runtime.model import DEMO_MODEL
from sinmdm.train.checkpoint import BEST, load_config, read_log
from sinmdm.train.watch import COPYING, PEAKED, STALLED, WatchState

from .conftest import DEMO_CLIP, run_cli

# (coverage, global diversity) rows of the table and the paper
PAPER_ROW, COPYING_ROW, DRIFTING_ROW = (98.1, 1.55), (100.0, 1.01), (75.6, 1.89)


def test_balance_ranks_a_shaking_model_below_a_steady_one():
    # logged checks of the Joe walk (bench/results/watched.json): the frame-norm stage's best
    # against the GroupNorm stage's, coverage / global diversity / jitter (x the clip's jerk)
    shaking, steady = balance(97.07, 1.5957, 5.205), balance(90.92, 1.1702, 2.516)
    assert shaking < steady
    assert balance(97.07, 1.5957, 2.0) == balance(97.07, 1.5957)  # within the limit: no effect
    assert not in_band({"coverage": 97.07, "global_diversity": 1.5957, "jitter_ratio": 5.205})


def test_balance_ranks_a_model_that_loses_the_clip_s_turning_below_one_that_keeps_it():
    # logged checks of the heading-frame walk (2026-12-06): the frame-norm stage's first check
    # (samples turn 15.9 deg/s away from the clip's) against the GroupNorm stage's best (8.1)
    astray, turning = balance(100.0, 1.7271, 0.442, 15.86), balance(100.0, 1.2962, 2.276, 8.11)
    assert astray < turning
    assert balance(100.0, 1.2962, 2.276, 8.11) == balance(100.0, 1.2962, 2.276)  # within the floor: no effect
    assert not in_band({"coverage": 100.0, "global_diversity": 1.73, "turning_distance_deg_s": 15.86,
                        "turning_allowed_deg_s": 10.0})


def test_balance_ranks_feet_that_glide_below_feet_that_plant():
    # whole-clip Xia normal (2026-12-07): the frame-norm stage's best check (balance 1.05, its feet
    # planted on 12 % of frames) against the GroupNorm stage's (0.81, 29 %); the clip's: 48 %
    needed = 0.5 * 0.48
    gliding = balance(100.0, 1.5898, 2.492, 3.56, 13.81, 0.016, 0.1, 0.12, needed)
    planting = balance(100.0, 1.3113, 3.7, None, 10.0, None, 0.1, 0.29, needed)
    assert gliding < planting
    assert balance(100.0, 1.3113, None, planted_share=0.29, planted_needed=needed) == balance(100.0, 1.3113)
    assert not in_band({"coverage": 100.0, "global_diversity": 1.59, "planted_share": 0.12, "planted_needed": needed})


def test_balance_ranks_the_paper_above_copying_and_drifting():
    assert balance(*PAPER_ROW) > balance(*DRIFTING_ROW) and balance(*PAPER_ROW) > balance(*COPYING_ROW)
    # The table (coverage, global, local): the paper's harmonic mean (maxima = the
    # 90th percentile) ranks the drifting recipe first; the balance ranks it last.
    table = [[98.1, 1.55, 1.12], [89.6, 1.48, 1.28], [75.6, 1.89, 1.59], [84.0, 1.53, 1.32]]
    hm = harmonic_mean(table, [True] * 3, [None] * 3)
    assert max(range(4), key=hm.__getitem__) == 2
    ours = [balance(c, g) for c, g, _ in table]
    assert max(range(4), key=ours.__getitem__) == 0 and min(range(4), key=ours.__getitem__) == 2


def scores(coverage: float, diversity: float, step_ratio: float = 1.0) -> dict:
    return {"coverage": coverage, "global_diversity": diversity, "balance": balance(coverage, diversity),
            "root_step_max_ratio": step_ratio}


def test_watch_keeps_the_best_and_stops_after_patience_in_band():
    state = WatchState()
    assert state.update(200, scores(60, 2.0)) and state.best_step == 200
    assert state.update(400, scores(97, 1.6)) and in_band(state.best)
    assert not state.update(600, scores(99, 1.2))  # copying sets in
    assert not state.update(800, scores(100, 1.4, step_ratio=3.0))  # a teleport is never kept
    assert state.should_stop(3, scores(100, 1.4)) is None
    assert not state.update(1000, scores(100, 1.05))
    assert state.should_stop(3, scores(100, 1.05)) == PEAKED and state.best_step == 400
    assert WatchState.from_dict(state.to_dict()) == state


def test_watch_does_not_stop_before_the_band():
    state = WatchState()
    for step, coverage in enumerate((50, 60, 55, 58, 57), start=1):
        state.update(step * 200, scores(coverage, 2.0))
    assert state.since_best == 3 and state.should_stop(3, scores(57, 2.0)) is None


def test_watch_stops_a_copying_run_short_of_the_band():
    """The walk's curve: coverage reaches the band while diversity falls below it."""
    state = WatchState()
    for step, (coverage, diversity) in enumerate(((50, 1.51), (74, 1.47), (91, 1.17), (96, 1.15), (98, 1.1),
                                                   (99, 1.05)), start=1):
        state.update(step * 200, scores(coverage, diversity))
    assert state.best_step == 600 and state.should_stop(3, scores(99, 1.05)) == COPYING


def test_watch_stops_a_run_that_loses_coverage_short_of_the_band():
    """The Mixamo idle's checks (planted_s9): best at step 400, then coverage and diversity fall
    together; the crab's (a run still learning, its coverage moving a few points) goes on."""
    idle = WatchState()
    for step, (coverage, diversity) in enumerate(((70.6, 1.59), (87.5, 1.49), (84.1, 1.36), (84.8, 1.34),
                                                   (79.7, 1.31)), start=1):
        idle.update(step * 200, scores(coverage, diversity))
    assert idle.best_step == 400 and idle.should_stop(3, scores(79.7, 1.31)) == STALLED
    crab = WatchState()
    for step, (coverage, diversity) in enumerate(((62.2, 1.5), (63.9, 1.42), (65.1, 1.38), (61.6, 1.41), (64.3, 1.33),
                                                   (63.8, 1.31), (63.0, 1.32)), start=1):
        crab.update(step * 200, scores(coverage, diversity))
    assert crab.since_best == 4 and crab.should_stop(3, scores(63.0, 1.32)) is None


def test_checks_can_score_what_sample_gives_with_the_foot_cleanup():
    """The scorer samples with the cleanup when its settings ask: the demo's feet slide
    25 cm/s without it (BENCHMARKS.md), and far less with it."""
    model, clip = load_model(DEMO_MODEL), read_bvh(DEMO_CLIP)
    raw, cleaned = (ClipScorer(clip, CheckSettings(samples=2, steps=5, cleanup=c), fps=model.codec.fps,
                               window=model.trained_window).check(model) for c in (False, True))
    assert cleaned["foot_skating_cm_s"] < 0.5 * raw["foot_skating_cm_s"]


@pytest.fixture(scope="module")
def watched_run(tmp_path_factory):
    run_dir = tmp_path_factory.mktemp("watched") / "run"
    result = run_cli("sinmdm", "train", str(DEMO_CLIP), "--out", str(run_dir), "--steps", "10", "--width", "32",
                     "--batch", "4", "--crop", "48", "--checkpoint-every", "5", "--check-every", "5", "--check-cleanup",
                     check=True)
    output = result.stdout + result.stderr
    assert "check at step 5" in output and "kept step" in output
    return run_dir


def test_watched_run_logs_checks_and_keeps_best(watched_run):
    checks = [r for r in read_log(watched_run) if "check" in r]
    assert [r["step"] for r in checks] == [5, 10]
    for record in checks:
        assert {"coverage", "global_diversity", "local_diversity", "balance", "jitter_ratio",
                "check_seconds"} <= set(record["check"])
    config = load_config(watched_run)
    assert config["finished"] and config["watch"]["checks"] == 2 and config["train"]["check_cleanup"]
    assert config["watch"]["best_step"] in (5, 10) and (watched_run / BEST).exists()
    sampling = config["sampling"]
    assert sampling["steps"] in (10, 20, 30, 50) and sampling["smooth"] in (0.0, *SMOOTH_CANDIDATES)
    assert [t["smooth"] for t in sampling["trials"]][:5] == [0.0] * 5  # then smoothing, tried on shaky samples
    assert sampling["smooth"] in [t["smooth"] for t in sampling["trials"]]
    info = json.loads(run_cli("sinmdm", "info", str(watched_run), "--json", check=True).stdout)
    assert info["watch"]["best_step"] == config["watch"]["best_step"] and info["sampling"] == config["sampling"]
    rich = run_cli("sinmdm", "info", str(watched_run), check=True)
    assert "quality checks" in rich.stdout + rich.stderr


def test_export_carries_the_choice_and_sample_uses_it(watched_run, tmp_path):
    run_cli("sinmdm", "export", str(watched_run), "--out", str(tmp_path / "m.onnx"), check=True)
    model_path = tmp_path / "m_w48.onnx"
    from sinmdm.runtime import load_model

    model = load_model(model_path)
    config = load_config(watched_run)
    provenance = model.metadata["provenance"]
    assert provenance["checkpoint"]["checkpoint"] == "best"
    assert provenance["checkpoint"]["step"] == config["watch"]["best_step"]
    assert model.metadata["sampling_defaults"] == {k: config["sampling"][k] for k in ("steps", "hop", "smooth")}
    assert model.default_steps == config["sampling"]["steps"] and model.default_smooth == config["sampling"]["smooth"]
    out = run_cli("sinmdm-run", "sample", str(model_path), "--frames", "96", "--out", str(tmp_path / "s"), "--json",
                  check=True)
    summary = json.loads(out.stdout)
    assert (summary["steps"], summary["hop"], summary["smooth"]) == tuple(config["sampling"][k] for k in ("steps", "hop", "smooth"))
    forced = json.loads(run_cli("sinmdm-run", "sample", str(model_path), "--frames", "96", "--steps", "7", "--hop", "12",
                                "--out", str(tmp_path / "f"), "--json", check=True).stdout)
    assert forced["steps"] == 7 and forced["hop"] == 12
    last = tmp_path / "last.onnx"
    run_cli("sinmdm", "export", str(watched_run), "--out", str(last), "--checkpoint", "last", check=True)
    assert load_model(tmp_path / "last_w48.onnx").metadata["provenance"]["checkpoint"]["checkpoint"] == "last"


def test_fallbacks_only_for_a_copying_run_with_budget_left():
    from types import SimpleNamespace

    from sinmdm.train.presets import preset
    from sinmdm.train.trainer import _fallback_stages, _falls_back, load_clip

    config = preset("cpu")
    walk = SimpleNamespace(codec=load_clip(DEMO_CLIP, 30.0, {}).codec)
    copying = SimpleNamespace(config=config, stopped=f"{COPYING}: ...", step=1200, clip=walk)
    norm, feet = _fallback_stages(copying)
    assert (norm.norm, norm.foot_loss, norm.fallback_norm, norm.fallback_foot_loss) == ("frame", 0.0, None, 0.0)
    assert (feet.norm, feet.foot_loss, feet.foot_loss_target, feet.fallback_norm) == ("group", 0.001, "clip", None)
    assert _falls_back(copying)
    assert not _falls_back(SimpleNamespace(config=config, stopped=f"{PEAKED}: ...", step=1200, clip=walk))
    assert not _falls_back(SimpleNamespace(config=config, stopped=None, step=config.steps, clip=walk))
    assert not _falls_back(SimpleNamespace(config=config, stopped=f"{COPYING}: ...", step=config.steps - 100, clip=walk))
    assert not _fallback_stages(SimpleNamespace(config=norm, stopped=f"{COPYING}: ...", step=100, clip=walk))
    asked = SimpleNamespace(config=config.with_overrides(foot_loss=0.0003), stopped=f"{COPYING}: ...", step=100, clip=walk)
    assert [s.norm for s in _fallback_stages(asked)] == ["frame"]  # a run with its own foot loss keeps it
    no_feet = SimpleNamespace(codec=SimpleNamespace(trajectory_joint=None, contact_joints=[]))
    assert [s.norm for s in _fallback_stages(SimpleNamespace(config=config, stopped=f"{COPYING}: ...", clip=no_feet))] == ["frame"]
    stalled = SimpleNamespace(config=config, stopped=f"{STALLED}: ...", step=1000, clip=walk)
    (edges,) = _fallback_stages(stalled)
    assert (edges.norm, edges.crop_edges, edges.foot_loss, edges.foot_loss_target) == ("group", 0.25, 0.0003, "clip")
    assert _falls_back(stalled)
    (only_edges,) = _fallback_stages(SimpleNamespace(config=config, stopped=f"{STALLED}: ...", clip=no_feet))
    assert (only_edges.crop_edges, only_edges.foot_loss) == (0.25, 0.0)


@pytest.mark.parametrize("reason, tried", [
    (COPYING, [("norm-frame", 5, 5), ("norm-group-foot-loss", 10, 5)]),
    (STALLED, [("norm-group-crop-edges-foot-loss", 5, 5)]),
])
def test_a_stopped_run_trains_its_fallback_stages(tmp_path, monkeypatch, reason, tried):
    """Real training: the watch's verdict is forced to `reason` at every check, so each stage stops
    at its first check and the next one takes the steps left."""
    from sinmdm.train.presets import TrainConfig
    from sinmdm.train.trainer import train

    monkeypatch.setattr(WatchState, "should_stop", lambda self, patience, latest: reason)
    config = TrainConfig(preset="test", steps=30, batch=4, crop=48, width=32, checkpoint_every=5, check_every=5,
                         fallback_norm="frame", fallback_foot_loss=0.001, stalled_crop_edges=0.25,
                         stalled_foot_loss=0.0003, bf16=False)
    result = train(DEMO_CLIP, tmp_path / "run", config)
    stages = result["stages"]
    assert [(s["dir"], s["from_step"], s["steps"]) for s in stages] == tried
    last = load_config(tmp_path / "run" / tried[-1][0])
    assert last["foot_loss"]["on"] and last["train"]["foot_loss_target"] == "clip"
    assert last["train"]["steps"] == config.steps - tried[-1][1] and last["train"]["stalled_crop_edges"] == 0.0
    balances = [s["best"]["balance"] for s in stages]
    assert result["stage"]["dir"] == stages[balances.index(max(balances))]["dir"]
    assert sum(s["chosen"] for s in stages) == int(result["stage"]["chosen"])
    assert load_config(tmp_path / "run")["stages"] == stages
    info = run_cli("sinmdm", "info", str(tmp_path / "run"), check=True)
    shown = info.stdout + info.stderr
    assert all(f"fallback stage {name}" in shown for name, _, _ in tried)
    with pytest.raises(Exception, match="is finished"):  # every stage done: nothing left to resume
        train(DEMO_CLIP, tmp_path / "run", config, resume=True)


def test_export_follows_a_chosen_second_stage(watched_run, tiny_run, tmp_path):
    """A run whose second stage was chosen exports the stage's weights and model config."""
    import shutil

    from sinmdm.runtime import load_model

    run_dir = tmp_path / "run"
    shutil.copytree(watched_run, run_dir)
    shutil.copytree(tiny_run, run_dir / "norm-frame")
    config = json.loads((run_dir / "config.json").read_text())
    config["stage"] = {"dir": "norm-frame", "norm": "frame", "steps": 10, "from_step": 10, "best": None, "chosen": True}
    (run_dir / "config.json").write_text(json.dumps(config))
    run_cli("sinmdm", "export", str(run_dir), "--out", str(tmp_path / "s.onnx"), check=True)
    run_cli("sinmdm", "export", str(tiny_run), "--out", str(tmp_path / "t.onnx"), check=True)
    staged, tiny = load_model(tmp_path / "s_w48.onnx"), load_model(tmp_path / "t_w48.onnx")
    assert staged.metadata["model_id"] == tiny.metadata["model_id"]
    provenance = staged.metadata["provenance"]
    assert provenance["checkpoint"]["stage"] == "norm-frame" and provenance["checkpoint"]["run_step"] == 10 + 10
    assert provenance["train"] == load_config(tiny_run)["train"] and provenance["steps"] == 10 + 10


def test_damaged_best_checkpoint_is_refused_by_export(watched_run, tmp_path):
    import shutil

    from .test_checkpoints import assert_one_line_error, flip_bytes

    run_dir = Path(shutil.copytree(watched_run, tmp_path / "run"))
    flip_bytes(run_dir / BEST)
    result = run_cli("sinmdm", "export", str(run_dir), "--out", str(tmp_path / "m.onnx"))
    assert_one_line_error(result, str(run_dir / BEST), "corrupted")
    assert not list(tmp_path.glob("*.onnx"))


class _FixedScores:
    """A scorer that returns given scores per (steps, hop, smooth): the selection rule alone."""

    def __init__(self, table: dict):
        self.table = table

    def check(self, model, steps=None, hop=None, smooth=0.0) -> dict:
        coverage, diversity, jitter = self.table.get((steps, hop, smooth), self.table["default"])
        return {"coverage": coverage, "global_diversity": diversity, "local_diversity": diversity, "jitter_ratio": jitter,
                "turning_distance_deg_s": 0.0, "turning_allowed_deg_s": 10.0, "root_step_max_ratio": 1.0, "eval_preset": "mixamo24", "check_seconds": 0.0,
                "balance": balance(coverage, diversity, jitter)}


def test_smoothing_is_kept_where_it_calms_jittery_samples_for_little_diversity():
    # the heading-frame walk's calibration: 2.80x -> 1.27x for 0.03 of diversity (the balance fell 0.024)
    from sinmdm.eval.balance import choose_sampling

    calm = _FixedScores({"default": (100.0, 1.35, 2.80), (10, 48, 1.0): (99.9, 1.32, 1.27)})
    assert choose_sampling(None, calm, 64)["smooth"] == 1.0
    costly = _FixedScores({"default": (100.0, 1.35, 2.80), (10, 48, 1.0): (99.9, 1.20, 1.27)})  # 0.15 of diversity
    assert choose_sampling(None, costly, 64)["smooth"] == 0.0
    steady = _FixedScores({"default": (100.0, 1.35, 1.80), (10, 48, 1.0): (99.9, 1.32, 1.10)})  # not jittery: balance rules
    assert choose_sampling(None, steady, 64)["smooth"] == 0.0


def test_checks_as_sampled_score_a_shaking_checkpoint_as_calibration_will_smooth_it():
    # Xia proud's checks with the cleanup: step 200 at 100 / 1.34 shook 3.4x the clip (balance 0.88) and lost
    # to step 400 at 100 / 1.17 / 2.6x (0.90); smoothed as calibration smooths, step 200 is the better one
    shaking = _FixedScores({"default": (100.0, 1.344, 3.405), (None, None, SMOOTH_CANDIDATES[0]): (100.0, 1.31, 1.8)})
    step_200 = ClipScorer.check_as_sampled(shaking, None)
    assert step_200["smooth"] == SMOOTH_CANDIDATES[0] and step_200["balance"] > 1.0
    step_400 = ClipScorer.check_as_sampled(_FixedScores({"default": (100.0, 1.165, 2.557)}), None)
    assert step_400["smooth"] == 0.0 and step_200["balance"] > step_400["balance"]
    # a check that could not beat the best even with calm samples is not sampled twice
    assert ClipScorer.check_as_sampled(shaking, None, to_beat=1.2)["smooth"] == 0.0
    # smoothing that costs the balance and 0.4 of diversity is not what calibration keeps: the raw scores stand
    costly = _FixedScores({"default": (100.0, 1.6, 3.1), (None, None, SMOOTH_CANDIDATES[0]): (100.0, 1.2, 1.8)})
    assert ClipScorer.check_as_sampled(costly, None)["smooth"] == 0.0
