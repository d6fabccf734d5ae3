"""``foveatrack gimbal`` commands called through the group's own entry point."""

import pytest

from foveatrack.cli import gimbal_cmd


def test_curves_plot_for_two_unit_seeds(tmp_path, capsys):
    out = tmp_path / "curves.png"
    assert gimbal_cmd.main(["curves", "--plot", str(out), "--unit-seeds", "0", "1"]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert capsys.readouterr().out.strip() == str(out)


@pytest.mark.parametrize(
    "argv,needle",
    [
        (["serve", "--address", "0"], "--address"),
        (["serve", "--baud", "0"], "--baud"),
        (["serve", "--family", "pts-999"], "family"),
        (["curves", "--plot", "/nonexistent/dir/x.png"], "--plot"),
    ],
)
def test_user_errors_are_one_line_messages(argv, needle, capsys):
    assert gimbal_cmd.main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("foveatrack: error:") and needle in err and "Traceback" not in err
