"""A speed table a user supplies (paper App. D.4) is checked for what the tracker would steer wrong by:
speeds that fall as the byte rises, and bytes it has no speed for.  Such tables still load and run
(the inverse works on any table with a speed > 0: test_control_and_table.py); they are said, naming
the bytes, at the daemon's start and by ``daemon --check`` (tests/daemon/test_config_gaps.py)."""

import json
import re
from pathlib import Path

import pytest

from foveatrack.speed_table import MAX_INTERPOLATED_RUN, TURBO, AxisTable, SpeedEntry, SpeedTable

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "pts303h-unit3-speed-table.json"


def _axis(axis, speeds, sigma=0.01):
    """An axis table from {byte: speed}."""
    return AxisTable(axis, tuple(SpeedEntry(b, v, sigma) for b, v in speeds.items()))


def _linear(bytes_, top=15.0):
    return {b: (b + 1) / 64 * top for b in bytes_}


def test_tables_that_steer_right_raise_nothing():
    # the measured example (its slow bytes scatter about 0 within their sigmas: pan 1 0.003, 2 0.002),
    # the nominal table, and every 4th byte from 4 (a PTS-303H barely turns below byte 4)
    assert SpeedTable.load(EXAMPLE).problems() == []
    assert SpeedTable.nominal().problems() == []
    assert _axis("tilt", _linear(list(range(4, 64, 4)) + [63])).problems() == []


def test_a_speed_below_a_lower_bytes_names_both_bytes():
    d = json.loads(EXAMPLE.read_text())
    pan = d["axes"]["pan"]["entries"]
    i16, i20 = [k for k, e in enumerate(pan) if e["byte"] in (16, 20)]
    pan[i16]["speed"], pan[i20]["speed"] = pan[i20]["speed"], pan[i16]["speed"]    # two rows swapped
    problems = SpeedTable.from_dict(d).problems()
    assert len(problems) == 1, problems
    assert problems[0].startswith("pan speeds fall as the speed byte rises: byte 20 (2.126 deg/s) is slower than "
                                  "byte 16 (2.799)"), problems


def test_a_fall_counts_beyond_three_sigma_of_the_two_speeds():
    # byte 10 below byte 8 by 3 sigma of the two (hypot(0.1, 0.1) * 3 = 0.424): noise, not a fall; beyond it, said
    def falls(drop):
        ax = AxisTable("tilt", (SpeedEntry(0, 0.0, 0.01), SpeedEntry(4, 1.0, 0.01), SpeedEntry(8, 2.0, 0.1),
                                SpeedEntry(10, 2.0 - drop, 0.1), *(SpeedEntry(b, b / 4, 0.01) for b in range(12, 64, 4)),
                                SpeedEntry(63, 15.75, 0.01)))
        return [p for p in ax.problems() if "fall" in p]
    assert falls(0.42) == []
    said = falls(0.43)
    assert len(said) == 1 and "byte 10 (1.57 deg/s) is slower than byte 8 (2)" in said[0], said


def test_a_turbo_slower_than_the_fastest_byte_is_said():
    speeds = _linear(range(64))
    ax = AxisTable("pan", tuple(SpeedEntry(b, v, 0.01) for b, v in speeds.items()) + (SpeedEntry(TURBO, 12.0, 0.01),))
    said = ax.problems()
    assert len(said) == 1 and "turbo (12 deg/s) is slower than byte 63 (15)" in said[0], said


def test_bytes_without_a_speed_are_named():
    # measured at 0, 16 and 24 only: 25-63 never sent (the fastest turn is byte 24's), 1-15 interpolated
    problems = _axis("tilt", _linear([0, 16, 24], top=2.0)).problems()
    assert len(problems) == 2, problems
    assert re.search(r"tilt bytes 25-63 have no speed.*never sent.*fastest tilt turn is 0\.78", problems[0])
    assert "more than 7 bytes in a row: 1-15 (between 0 and 16)" in problems[1]
    # what it says of them holds for this table (known at 0, 16, 24, not "only at 4, 8, 16, 32 and 63"),
    # and the advice is the rule's (every 8th byte passes), not "every 4th"
    assert "the speeds there are interpolated guesses; measure at least every 8th byte (a table known only at " \
           "4, 8, 16, 32 and 63 once steered the tracker several percent off)" in problems[1], problems[1]
    assert "every 4th" not in problems[1] and "known only at 4, 8, 16, 32 and 63, the tracker's" not in problems[1]
    # from byte 24 up: 0-23 never sent, the slowest turn is byte 24's; 7 bytes in a row interpolated is not said
    problems = _axis("pan", _linear(range(24, 64, MAX_INTERPOLATED_RUN + 1))).problems()
    assert len(problems) == 2 and "pan bytes 0-23 have no speed" in problems[0] and "56" in problems[1], problems
    assert "pan bytes 57-63 have no speed" in problems[1]


def test_an_axis_with_turbo_only_says_so():
    ax = AxisTable("pan", (SpeedEntry(TURBO, 20.0, 0.1),))
    assert ax.problems() == ["pan bytes 0-63 have no speed: none is ever sent (turbo only)"]


def test_a_table_with_problems_still_loads_and_inverts(tmp_path):
    t = SpeedTable(_axis("pan", {0: 0.0, 10: 5.0, 20: 3.0, 63: 15.0}), _axis("tilt", {0: 0.0, 63: 2.0}))
    p = tmp_path / "t.json"
    t.save(p)
    back = SpeedTable.load(p)
    assert back.pan.byte_for_speed(5.0) == 10
    assert len(back.problems()) == 3      # pan falls, pan and tilt interpolated over long runs


def test_a_scenes_speed_table_file_is_judged_as_a_daemon_configs_is(tmp_path, capsys):
    # a scene flying a user's table got none of the daemon's checks: simulate ran it silently
    from foveatrack.cli import main
    from sim.scene import load_scene

    d = json.loads(EXAMPLE.read_text())
    pan = d["axes"]["pan"]["entries"]
    i16, i20 = [k for k, e in enumerate(pan) if e["byte"] in (16, 20)]
    pan[i16]["speed"], pan[i20]["speed"] = pan[i20]["speed"], pan[i16]["speed"]
    (tmp_path / "swapped.json").write_text(json.dumps(d))
    scene = tmp_path / "s.toml"
    scene.write_text('[scene]\nduration_s = 0.3\n[gimbal]\nspeed_table = "swapped.json"\n'
                     '[[target]]\n[target.trajectory]\ntype = "straight"\nstart_m = [12.0, 0.0, 1.0]\n'
                     'velocity_m_s = [0.0, 0.5, 0.0]\n')
    said = [w for w in load_scene(scene).warnings() if "speed_table" in w]
    assert len(said) == 1 and "'" + str(tmp_path / "swapped.json") + "'" in said[0], said
    assert "byte 20 (2.126 deg/s) is slower than byte 16 (2.799)" in said[0]
    assert main(["simulate", str(scene), "--out", str(tmp_path / "run")]) == 0
    assert "byte 20 (2.126 deg/s) is slower than byte 16" in capsys.readouterr().err
    # the simulated unit's own tables are not files: nothing to say
    scene.write_text(scene.read_text().replace('"swapped.json"', '"nominal"'))
    assert not [w for w in load_scene(scene).warnings() if "speed_table" in w]


def test_bytes_above_the_highest_that_may_be_sent_are_not_missing():
    # a table measured under [head] max_tilt_byte = 40 (calibrate --config drops the bytes above it)
    table = _axis("tilt", _linear(list(range(0, 41, 4))))
    assert table.problems(max_byte=40) == []
    assert [p for p in table.problems() if "41-63 have no speed" in p]          # no limit: every byte counts
    said = table.problems(max_byte=45)
    assert len(said) == 1 and "tilt bytes 41-45 have no speed" in said[0], said
    # an interpolated run counts only up to the limit: 24 -> 63 leaves 25-40 unknown below a limit of 40
    assert len(_axis("pan", _linear([0, 4, 8, 12, 16, 20, 24, 63])).problems(max_byte=31)) == 0
    assert "25-62 (between 24 and 63)" in _axis("pan", _linear([0, 4, 8, 12, 16, 20, 24, 63])).problems(max_byte=40)[0]
    both = SpeedTable(_axis("pan", _linear(range(0, 41, 4))), table)
    assert both.problems({"pan": 40, "tilt": 40}) == [] and len(both.problems()) == 2
