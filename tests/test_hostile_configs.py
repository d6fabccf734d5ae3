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
