"""Hostile configuration files (issue 32): every one is the one-line error the rest of the config
gives, never a traceback (found by mutation fuzzing, scripts/fuzz_files.py)."""

import os

import pytest

from foveatrack.cli import main
from foveatrack.errors import UserError

EXAMPLE = os.path.join(os.path.dirname(__file__), "..", "examples", "daemon-virtual.toml")


def _one_error_line(capsys, args):
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


@pytest.mark.parametrize("cmd", [["daemon", "--check", "--config"], ["simulate", "--duration", "1"]])
def test_toml_nested_1000_deep_is_a_one_line_error(tmp_path, capsys, cmd):
    p = tmp_path / "deep.toml"
    p.write_text(open(EXAMPLE).read() + "x = " + "[" * 1000 + "]" * 1000 + "\n")
    line = _one_error_line(capsys, [*cmd, str(p)] if cmd[0] == "daemon" else [cmd[0], str(p), *cmd[1:]])
    assert "nested too deep" in line and str(p) in line


def test_a_special_file_as_a_speed_table_is_refused_without_reading_it():
    from foveatrack.speed_table import SpeedTable

    with pytest.raises(UserError, match="not a regular file"):
        SpeedTable.load("/dev/zero")


ROOT = os.path.join(os.path.dirname(__file__), "..")
SCENE = os.path.join(ROOT, "scenes", "fig12-tracking.toml")


def _daemon_config_without_tracker_tables(tmp_path) -> str:
    import re
    import shutil

    for name in os.listdir(os.path.join(ROOT, "examples")):
        if name.endswith(".json"):      # the speed table the config names, beside it
            shutil.copy(os.path.join(ROOT, "examples", name), tmp_path / name)
    text = re.sub(r"\n\[tracker(\.[a-z]+)?\][^\n]*\n(?:(?!\n\[).)*", "\n", open(EXAMPLE).read(), flags=re.S)
    return text


def test_a_scene_preset_that_is_not_a_name_is_named(tmp_path, capsys):
    # before: "TypeError: unhashable type: 'list'"
    p = tmp_path / "s.toml"
    p.write_text(open(SCENE).read().replace('preset = "mid40"', "preset = []"))
    line = _one_error_line(capsys, ["simulate", str(p), "--duration", "0.2"])
    assert "[lidar]: preset must be a name" in line and "got []" in line


def test_a_tracker_that_is_not_a_table_is_named_in_the_daemon_config_and_in_replay(tmp_path, capsys):
    # before: "TypeError: 'int' object is not iterable" from deep inside the loader
    p = tmp_path / "d.toml"
    p.write_text("tracker = 1\n" + _daemon_config_without_tracker_tables(tmp_path))
    line = _one_error_line(capsys, ["daemon", "--check", "--config", str(p)])
    assert "[tracker] must be a table, got 1" in line
    rec = os.path.join(ROOT, "tests", "recording", "fixtures", "fig12-v2.mcap")
    line = _one_error_line(capsys, ["replay", rec, "--tracker-config", str(p)])
    assert "[tracker] must be a table, got 1" in line


def test_a_nul_in_the_head_port_is_named(tmp_path, capsys):
    # before: "ValueError: embedded null byte" when the port was opened
    p = tmp_path / "d.toml"
    p.write_text(open(EXAMPLE).read().replace('port = "/tmp/ft-head"', 'port = "/tmp/ft\\u0000head"'))
    line = _one_error_line(capsys, ["daemon", "--check", "--config", str(p)])
    assert "[head]: port must be" in line and "NUL" in line


def test_a_scene_with_too_many_targets_is_refused_before_it_runs(tmp_path, capsys):
    # before: a scene of 100 000 targets ran on with no cap
    import re

    text = open(SCENE).read()
    target = re.search(r"\[\[target\]\].*?(?=\n\[)", text, re.S).group(0)
    p = tmp_path / "swarm.toml"
    p.write_text(text + "\n" + (target + "\n") * 300)
    line = _one_error_line(capsys, ["simulate", str(p), "--duration", "0.2"])
    assert "301 [[target]] tables; at most 256" in line
