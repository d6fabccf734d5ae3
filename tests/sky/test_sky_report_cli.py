"""scripts/sky_tracks_report.py refuses what it cannot run before any run starts, with one line that
names the bad argument (exit status 2), and runs a tiny report."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCENE = str(ROOT / "scenes" / "two-drones-crossing.toml")   # the tests may run from any directory


@pytest.fixture(scope="module")
def report():
    spec = importlib.util.spec_from_file_location("sky_tracks_report", ROOT / "scripts" / "sky_tracks_report.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def refused(report, capsys, *argv) -> str:
    """main(argv)'s exit status must be 2; its stderr, for the message, without a traceback."""
    try:
        status = report.main([str(a) for a in argv])
    except SystemExit as exc:      # argparse's refusals
        status = exc.code
    err = capsys.readouterr().err
    assert status == 2, err
    assert "Traceback" not in err
    assert "sky_tracks_report.py: error:" in err
    return err


@pytest.mark.parametrize("argv, names", [
    (["--seeds", "0"], "--seeds"),
    (["--seeds", "-1"], "--seeds"),
    (["--seeds", "two"], "--seeds"),
    (["--duration", "0"], "--duration"),
    (["--duration", "-3"], "--duration"),
    (["--duration", "nan"], "--duration"),
])
def test_a_count_or_time_out_of_range_is_refused_up_front(report, capsys, argv, names):
    err = refused(report, capsys, SCENE, *argv)
    assert names in err


@pytest.mark.parametrize("item", ["min_points", "attention.revisit_s=abc", "=3", "attention..revisit_s=2",
                                  "warmup_s=", "warmup_s=nan", "warmup_replay=yes"])
def test_a_set_item_not_key_equals_number_or_boolean_is_refused_naming_it(report, capsys, item):
    err = refused(report, capsys, SCENE, "--set", item)
    assert "--set" in err and repr(item) in err


def test_set_values_are_booleans_integers_or_numbers(report):
    assert [report._set_item(t) for t in ("warmup_replay=false", "confirm_hits=3", "attention.revisit_s=2.8",
                                          "v0_sigma_m_s=-1e-1")] == [
        (("warmup_replay",), False), (("confirm_hits",), 3), (("attention", "revisit_s"), 2.8),
        (("v0_sigma_m_s",), -0.1)]


@pytest.mark.parametrize("argv, names", [
    ([SCENE, str(ROOT / "scenes" / "nope.toml")], "nope.toml"),
    ([SCENE, "--set", "min_pionts=3"], "min_pionts"),
    ([SCENE, "--set", "attention.revisit_s=-1"], "revisit_s"),
    ([SCENE, "--set", "min_points=2", "classifier.bogus=1"], "bogus"),
    ([SCENE, "--first-seed", "-1000"], "--first-seed"),
])
def test_a_user_error_is_one_line_before_any_run(report, capsys, argv, names):
    """A missing scene or a bad --set key is the scene's or the table's UserError, printed as the
    foveatrack command prints one (a line, exit status 2) before the first scene has run."""
    err = refused(report, capsys, *argv)
    assert names in err
    assert len(err.strip().splitlines()) == 1
    assert "frames in" not in err       # no run had started


def test_a_duration_shorter_than_a_frame_is_refused(report, capsys):
    """0.01 s is > 0 but no tracker frame: the figures of no frame divided by zero."""
    assert "--duration" in refused(report, capsys, SCENE, "--duration", "0.01")


def test_a_markdown_path_that_cannot_be_written_is_refused_before_any_run(report, capsys, tmp_path):
    """The page is written after every run: a missing directory used to be found minutes later."""
    unwritable = [Path("/proc/sky-report.md")] if Path("/proc/self").is_dir() else []   # even for root
    for path in (tmp_path / "no" / "such" / "x.md", tmp_path, *unwritable):
        err = refused(report, capsys, SCENE, "--markdown", path)
        assert "--markdown" in err and "frames in" not in err


def test_a_tiny_summary_only_run(report, capsys):
    """--summary-only prints what its help says (and docs/sky-tracks-figures.md's hour tables use): the
    summary, where the longest gaps went, the confusion matrix; no per-seed table."""
    assert report.main([SCENE, "--seeds", "1", "--duration", "1.5", "--summary-only"]) == 0
    out = capsys.readouterr().out
    assert "\n| two-drones-crossing | 1 | 0.00 | 2 | " in out
    assert report.GAP_HEAD in out and "## Confusion matrix" in out
    assert "## two-drones-crossing" not in out and "| seed |" not in out


def test_the_help_describes_every_argument_in_plain_text(report):
    parser = report.build_parser()
    assert all(a.help for a in parser._actions), [a.dest for a in parser._actions if not a.help]
    description = " ".join(parser.format_help().split("positional arguments:")[0].split())
    assert "sim.sky_summary.scan_allows_confirm_s" in description      # whole, not split by the wrap
    assert ":func:" not in description and "``" not in description
