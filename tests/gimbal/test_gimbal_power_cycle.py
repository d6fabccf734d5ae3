"""The virtual head's power cut behind a live link (issue 26): the model comes back at its power-on
pose, at rest, and obeys commands again; the served head does it on SIGUSR1 with its pty kept."""

import math

from gimbal.pelco import encode_pan_tilt
from gimbal.pts303h import PTS303H


def test_a_power_cycled_head_stands_at_its_power_on_pose_and_obeys_again():
    head = PTS303H(unit_seed=3, pan0_deg=2.0, tilt0_deg=1.0)
    head.receive(encode_pan_tilt(1, 1, 40, 1, 30), 0.0)
    head.advance_to(3.0)
    pan, tilt = head.angles_now(3.0)
    assert pan > 20.0 and tilt > 2.0
    head.power_cycle(3.0)
    assert head.angles_now(3.5) == (2.0, 1.0) and head.at_rest(3.5) and head.power_cycles == 1
    head.receive(encode_pan_tilt(1, -1, 40, 0, 0), 4.0)
    pan, tilt = head.angles_now(6.0)
    assert pan < 2.0 - 10.0 and tilt == 1.0 and math.isfinite(pan)


def test_the_served_head_power_cycles_with_its_pty_open(tmp_path):
    from sim.virtual_head import ManualClock, VirtualHeadServer, read_truth

    clock = ManualClock()
    truth = open(tmp_path / "t.jsonl", "w")
    with VirtualHeadServer(PTS303H(unit_seed=3), clock, truth=truth) as srv:
        path = srv.path
        with open(path, "wb", buffering=0) as tty:
            tty.write(encode_pan_tilt(1, 1, 40, 0, 0))
            srv.step(0.0)
            clock.t = 2.0
            srv.step(0.0)
            assert srv.head.angles_now(2.0)[0] > 10.0
            srv.power_cycle()
            assert srv.head.angles_now(2.0) == (0.0, 0.0)
            clock.t = 2.5
            srv.step(0.0)
    truth.close()
    rows = read_truth(str(tmp_path / "t.jsonl"))
    assert rows[-1]["pan_deg"] == 0.0 and any(r["pan_deg"] > 10.0 for r in rows)
