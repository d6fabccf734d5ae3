"""``[head] on_start = "home"`` (a review's findings): a homing write that fails during the start's
homing leaves the pose unknown until the link is back, then homes again -- whatever
``on_reconnect`` says (with "keep", the failed write once handed the pose to "keep" and it stayed
unknown for the rest of the run, in silence)."""

import time

import pytest

from daemon_procs import silent_lidar_table
from foveatrack.daemon import Daemon, load_config


@pytest.mark.parametrize("on_reconnect", ["keep", "stop", "home"])
def test_a_failed_write_of_the_starts_homing_homes_again_once_the_link_is_back(tmp_path, on_reconnect):
    cfg = tmp_path / "d.toml"
    cfg.write_text(f"""
{silent_lidar_table()}[head]
port = "loop://"
on_start = "home"
on_reconnect = "{on_reconnect}"
home_wait_s = 1.0
""")
    d = Daemon(load_config(cfg), log_path=str(tmp_path / "d.jsonl"), status=False, install_signals=False)
    d._open()
    clock = {"now": 0.0}
    down = {"until": None, "failed": False}
    head_class = type(d.head)

    class Flaky(head_class):       # the link drops with the first homing write, and is back 2 s later
        @property
        def connected(self):
            u = down["until"]
            return (u is None or clock["now"] >= u) and head_class.connected.fget(self)

    d.head.__class__ = Flaky
    sink = d.step.sink
    send_goal = sink.send_goal

    def failing_once(axis, goal, source):
        if not down["failed"]:
            down["failed"] = True
            down["until"] = clock["now"] + 2.0
            return False
        return send_goal(axis, goal, source)

    sink.send_goal = failing_once
    try:
        t0 = clock["now"] = time.monotonic()
        d._start()
        for i in range(100):                # 10 s of 10 Hz ticks
            clock["now"] = t0 + 0.1 * i
            d._watch_head_link(clock["now"])
    finally:
        d.stop_ev.set()
        d.client.close()
        d.head.close()
        if d.recorder is not None:
            d.recorder.close()
    assert down["failed"] and d.counters["head_homed"] == 1 and d.pose_state is None, (d.pose_state, d._home_policy)
