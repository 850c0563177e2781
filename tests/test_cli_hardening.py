"""The CLI boundary: every bad option is one line naming its flag (exit 2) before any work,
outputs are checked before sampling, crowds reproduce sample by sample, no traceback ever."""

from __future__ import annotations

import os
import sys

import pytest

from sinmdm.runtime import SamplingOptions, load_model
from sinmdm.runtime.applications import harmonize, load_reference, parse_frame_range
from sinmdm.runtime.errors import OptionError

from .conftest import DEMO_CLIP, call_cli, real_clip, run_cli

QUICK = ("--steps", "2")
EDITS = ("inbetween", "expand", "keyframes", "control", "harmonize")


def assert_one_line_error(result, flag: str) -> None:
    lines = result.stderr.splitlines()
    assert result.returncode == 2, result.stderr
    assert len(lines) == 1 and lines[0].startswith("error: ") and flag in lines[0], result.stderr


def run_bad(tmp_path, *args: str):
    out = tmp_path / "out"
    result = call_cli("sinmdm-run", *args, *QUICK, "--out", str(out))
    assert not out.exists() or not any(out.iterdir())
    return result


@pytest.mark.parametrize("args, flag", [
    (["--seconds", "inf"], "--seconds"),
    (["--seconds", "1e308"], "--seconds"),
    (["--seconds", "nan"], "--seconds"),
    (["--frames", "99999999999999999999"], "--frames"),
    (["--frames", "200000"], "--force"),
    (["--seed", "-1"], "--seed"),
    (["--seed", str(2**32)], "--seed"),
    (["--eta", "nan"], "--eta"),
    (["--eta", "2"], "--eta"),
    (["--hop", "0"], "--hop"),
    (["--margin", "-1"], "--margin"),
    (["--count", "0"], "--count"),
    (["--threads", "0"], "--threads"),
    (["--threads", "100000"], "--threads"),
    (["--name", "../x"], "--name"),
    (["--count", "abc"], "--count"),
])
def test_sample_bounds(tmp_path, args, flag):
    assert_one_line_error(run_bad(tmp_path, "sample", *args), flag)


@pytest.mark.parametrize("args, flag", [
    (["expand", "--before", "-1"], "--before"),
    (["expand", "--after", "-1"], "--after"),
    (["expand", "--before", "1000"], "--force"),  # capped before sampling (today: 2.9 GB, 10+ minutes)
    (["expand", "--ramp", "-1"], "--ramp"),
    (["inbetween", "--keep-start", "-0.2"], "--keep-start"),
    (["inbetween", "--keep-end", "1"], "--keep-end"),
    (["keyframes", "--every", "0"], "--every"),
    (["keyframes", "--hold", "-1"], "--hold"),
    (["keyframes", "--frames", "1,x"], "--frames"),
    (["harmonize", "--factor", "0"], "--factor"),
    (["harmonize", "--border", "-1"], "--border"),
    (["harmonize", "--frames", "200:100"], "start must be before stop"),
    (["harmonize", "--frames", "0:100000"], "outside the reference"),
    (["control", "--hop", "0"], "--hop"),
    (["control", "--joints", "upper-body", "--threads", "100000"], "--threads"),
    (["inbetween", "--seed", "-1"], "--seed"),
    (["inbetween", "--source-fps", "0"], "--source-fps"),
])
def test_edit_bounds(tmp_path, args, flag):
    assert_one_line_error(run_bad(tmp_path, *args, "--ref", str(DEMO_CLIP)), flag)


def test_reference_with_a_wrong_frame_rate_needs_source_fps(tmp_path):
    clip = real_clip("Joe_traj-example.bvh")  # Frame Time 1 s: a 30 fps file
    result = run_bad(tmp_path, "control", "--trajectory", "--ref", str(clip))
    assert_one_line_error(result, "--source-fps")
    call_cli("sinmdm-run", "control", "--trajectory", "--ref", str(clip), "--source-fps", "30", *QUICK,
            "--out", str(tmp_path / "ok"), check=True)
    assert len(list((tmp_path / "ok").glob("control_0000.bvh"))) == 1


@pytest.mark.parametrize("command", EDITS)
def test_every_edit_command_takes_every_sampling_option(command):
    text = run_cli("sinmdm-run", command, "--help", env={"COLUMNS": "200"}, check=True).stdout
    for flag in ("--count", "--seed", "--sampler", "--steps", "--eta", "--hop", "--margin", "--cleanup", "--threads",
                 "--out", "--name", "--format", "--npz", "--preview", "--force", "--json", "--source-fps"):
        assert flag in text, flag
    assert "--ref-fps" not in text


@pytest.mark.parametrize("command, extra", [
    ("inbetween", []), ("expand", []), ("keyframes", []), ("control", ["--joints", "upper-body"]),
    ("harmonize", []), ("harmonize", ["--frames", "20:60"]), ("harmonize", ["--joints", "upper-body"]),
])
def test_crowd_sample_reproduces_alone(tmp_path, command, extra):
    """Sample 7 of a crowd seeded 5 is byte-identical to a single run seeded 7 (partial
    harmonization included: each sample's base motion uses its own seed)."""
    args = ["sinmdm-run", command, "--ref", str(DEMO_CLIP), *extra, *QUICK]
    call_cli(*args, "--count", "3", "--seed", "5", "--out", str(tmp_path / "crowd"), check=True)
    call_cli(*args, "--seed", "7", "--out", str(tmp_path / "one"), check=True)
    name = f"{command}_0007.bvh"
    assert (tmp_path / "crowd" / name).read_bytes() == (tmp_path / "one" / name).read_bytes()


def test_partial_harmonization_api_matches_a_crowd():
    model = load_model()
    reference = load_reference(model, DEMO_CLIP)
    crowd = harmonize(model, reference, SamplingOptions(count=2, seed=3, steps=2), frame_range=(20, 60))
    alone = harmonize(model, reference, SamplingOptions(seed=4, steps=2), frame_range=(20, 60))
    assert (crowd.features[1] == alone.features[0]).all()


@pytest.mark.parametrize("field, value", [
    ("count", 0), ("count", 10_001), ("seed", -1), ("seed", 2**32), ("sampler", "euler"), ("steps", 0),
    ("steps", 1001), ("eta", float("nan")), ("eta", -0.1), ("hop", 0), ("margin", -1), ("count", 1.5),
])
def test_sampling_options_validate_with_the_api_name(field, value):
    with pytest.raises(OptionError) as info:
        SamplingOptions(**{field: value})
    assert info.value.option == field


def test_frame_range_parsing_is_in_the_runtime():
    assert parse_frame_range("10:20") == (10, 20)
    with pytest.raises(OptionError, match="START:STOP"):
        parse_frame_range("10-20")


def test_outputs_are_checked_before_sampling(tmp_path):
    """An existing file without --force, an unwritable --out and a bad --name fail before any
    sampling: with a crowd that would take minutes, the error comes at once and nothing is written."""
    crowd = ["sinmdm-run", "sample", "--count", "2000", "--frames", "2000"]
    (tmp_path / "taken").mkdir()
    (tmp_path / "taken" / "sample_0000.bvh").write_text("mine")
    result = call_cli(*crowd, "--out", str(tmp_path / "taken"))
    assert_one_line_error(result, "--force")
    assert (tmp_path / "taken" / "sample_0000.bvh").read_text() == "mine"
    (tmp_path / "file").write_text("")
    assert_one_line_error(call_cli(*crowd, "--out", str(tmp_path / "file" / "sub")), "file")
    assert_one_line_error(call_cli(*crowd, "--name", "/abs", "--out", str(tmp_path / "o")), "--name")
    edit = ["sinmdm-run", "expand", "--ref", str(DEMO_CLIP), "--count", "2000"]
    assert_one_line_error(call_cli(*edit, "--name", "a/b", "--out", str(tmp_path / "o")), "--name")


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes anywhere")
def test_unwritable_out_fails_before_sampling(tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        result = call_cli("sinmdm-run", "sample", "--count", "2000", "--frames", "2000", "--out", str(locked))
        assert_one_line_error(result, str(locked))
    finally:
        locked.chmod(0o700)


def test_convert_force_onto_a_directory_is_one_line(tmp_path):
    target = tmp_path / "dir.bvh"
    target.mkdir()
    result = call_cli("sinmdm-run", "convert", str(DEMO_CLIP), str(target), "--force")
    assert result.returncode == 2 and len(result.stderr.splitlines()) == 1 and result.stderr.startswith("error: ")
    assert target.is_dir() and not any(target.iterdir())


def test_unexpected_errors_are_one_line_and_debug_shows_the_traceback(tmp_path):
    """A model path that is a directory is not a user error the runtime foresees in every
    layer; whatever escapes is one `internal error` line, and --debug gives the traceback."""
    script = ("import sys; from sinmdm.cli.common import run_app; import typer\n"
              "app = typer.Typer(name='boom')\n"
              "@app.command()\n"
              "def go() -> None:\n    raise RuntimeError('unforeseen\\nsecond line')\n"
              "@app.command()\n"
              "def other() -> None:\n    pass\n"
              "run_app(app)()\n")
    plain = run_subprocess([sys.executable, "-c", script, "go"])
    assert plain.returncode == 1
    assert plain.stderr.splitlines() == ["internal error: RuntimeError: unforeseen second line "
                                         "(run with --debug for the traceback)"]
    debug = run_subprocess([sys.executable, "-c", script, "--debug", "go"])
    assert debug.returncode == 1 and "Traceback" in debug.stderr


def run_subprocess(argv):
    import subprocess

    return subprocess.run(argv, capture_output=True, text=True, timeout=120)


def test_long_paths_do_not_wrap_off_a_terminal(tmp_path):
    out = tmp_path / ("a-rather-long-directory-name-" * 4) / "samples"
    result = run_cli("sinmdm-run", "sample", "--frames", "70", *QUICK, "--out", str(out), env={"COLUMNS": "80"},
                     check=True)
    assert str(out) in result.stderr
    assert len(result.stderr.splitlines()) == 1


def test_execution_provider_option(tmp_path):
    """CPU is the default and the tested path; a provider this onnxruntime build lacks, or an
    unknown name, is one line naming --provider, before any work."""
    import onnxruntime as ort

    from sinmdm.runtime.model import PROVIDERS

    assert load_model(provider="cpu").denoisers[64].session.get_providers()[0] == "CPUExecutionProvider"
    with pytest.raises(OptionError) as unknown:
        load_model(provider="tpu")
    assert unknown.value.option == "provider"
    missing = next((name for name, ep in PROVIDERS.items() if ep not in ort.get_available_providers()), None)
    if missing is None:
        pytest.skip("every provider is installed here")
    out = tmp_path / "out"
    result = call_cli("sinmdm-run", "sample", "--provider", missing, *QUICK, "--out", str(out))
    assert result.returncode == 2 and result.stderr.startswith("error: --provider:") and result.stderr.count("\n") == 1
    assert not out.exists() or not any(out.iterdir())
