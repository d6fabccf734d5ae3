"""What networks do to a lidar's packets (issue 26), through the daemon's UDP port on loopback: the
virtual lidar behind a faulty network (``faulty_lidar.py``) that time-shifts, replays, re-sends,
duplicates or swaps its packets.  Each fault is counted under its own name, no real point is
discarded or reported lost, the sensor clock is not re-anchored, and tracking goes on.

Real points are counted exactly: the virtual lidar's real packets (100 points each, no-returns
included) against the daemon's ``lidar_accepted_points``; what the kernel dropped on the daemon's
socket (``/proc/net/udp``, a busy machine) is allowed for, packet by packet."""

import json
import os
import sys

import numpy as np
import pytest

from child_procs import dies_with_this_process
from daemon_procs import (HERE, SCENE, env, event, free_udp_port, log_events, stop_all,
                          terminate, wait_for, write_config)
from foveatrack.recording import RecordingReader
from gimbal.pts303h import PTS303H
from sim.loop import truth_speed_table

pytestmark = [pytest.mark.slow, pytest.mark.skipif(not os.path.exists("/proc/net/udp"), reason="needs /proc/net/udp")]

PKT = 100      # a Mid-40 packet's points


def udp_drops(port: int) -> int:
    """Datagrams the kernel dropped on the loopback socket bound to ``port`` (its receive buffer full)."""
    for line in open("/proc/net/udp").read().splitlines()[1:]:
        f = line.split()
        if f[1] == f"0100007F:{port:04X}":
            return int(f[-1])
    raise AssertionError(f"no socket bound to 127.0.0.1:{port}")


def _run(tmp_path, fault):
    import subprocess

    from test_faults import _head

    link, truth, rec, log = tmp_path / "head", tmp_path / "truth.jsonl", tmp_path / "rec.mcap", tmp_path / "d.jsonl"
    state = tmp_path / "lidar.json"
    bport = free_udp_port()
    table = tmp_path / "unit3.json"
    truth_speed_table(PTS303H(unit_seed=3)).save(table)
    cfg = write_config(tmp_path / "d.toml", link, rec, bport, speed_table=str(table))
    procs = {"head": _head(tmp_path, link, truth)}
    try:
        procs["daemon"] = subprocess.Popen(
            dies_with_this_process([sys.executable, "-m", "foveatrack", "daemon", "--config", str(cfg), "--log",
                                    str(log)]),
            env=env(), stdout=open(tmp_path / "d.out", "w"), stderr=open(tmp_path / "d.err", "w"),
            start_new_session=True)
        wait_for(lambda: event(log, "start"), 60, "the daemon to start", [procs["daemon"]])
        data_port = event(log, "start")["host_ports"]["data"]
        procs["lidar"] = subprocess.Popen(
            dies_with_this_process([sys.executable, str(HERE / "faulty_lidar.py"), str(SCENE), str(bport), str(truth),
                                    fault, str(state)]),
            env=env(), stdout=open(tmp_path / "l.out", "w"), stderr=open(tmp_path / "l.err", "w"),
            start_new_session=True)
        wait_for(lambda: state.exists(), 120, "the fault to be over", list(procs.values()))
        frames = lambda: ([e["frames"] for e in log_events(log) if e["event"] == "progress"] or [0])[-1]  # noqa: E731
        f0 = frames()
        wait_for(lambda: frames() >= f0 + 15, 60, "15 more frames", list(procs.values()))
        assert terminate(procs["lidar"]) == 0, (tmp_path / "l.err").read_text()
        drops = udp_drops(data_port)
        assert terminate(procs["daemon"]) == 0, (tmp_path / "d.err").read_text()
    finally:
        stop_all(procs)
    lidar = json.loads(state.read_text())
    stats = event(log, "stop")["stats"]
    return lidar, stats, drops, log, rec


# fault -> the guard's counter its injected packets land in
CASES = {"ahead": "early", "old5s": "stale", "resend50": "duplicate", "dup": "duplicate", "swap": "late",
         "resend2": "duplicate"}


@pytest.mark.parametrize("fault", list(CASES))
def test_a_network_fault_is_counted_by_name_and_loses_no_real_point(tmp_path, fault):
    lidar, stats, drops, log, rec = _run(tmp_path, fault)
    kind = CASES[fault]
    real, injected = lidar["real_sent"], lidar["injected"]
    assert lidar["fault_done"] and (injected > 0 or lidar["swapped"] > 0), lidar
    # the sensor clock is one clock throughout: no false jump, no rebase, no STOP for it
    assert stats.get("lidar_clock_jumps", 0) == 0 and stats.get("clock_epochs", 0) == 0, stats
    assert event(log, "tracker_rebased") is None and event(log, "lidar_clock_jump") is None
    # every real point accepted, but those the kernel dropped (a packet each); none thrown away later
    accepted, lost = stats["lidar_accepted_points"], stats["lidar_lost_slots"]
    assert (real - drops) * PKT <= accepted <= real * PKT, (accepted, real, drops)
    assert lost == real * PKT - accepted, (lost, real, accepted, drops)     # lost = what did not arrive
    assert stats["slicer_late_points"] == 0 and stats["queue_dropped_points"] == 0
    # the fault counted under its name (all of it, bar the kernel's drops), and nothing under another
    names = {"late": "lidar_late_points", "early": "lidar_early_points", "stale": "lidar_stale_points",
             "duplicate": "lidar_duplicate_points"}
    want = lidar["swapped"] * PKT if kind == "late" else injected * PKT
    assert want - drops * PKT <= stats[names[kind]] <= want, (stats[names[kind]], want, drops)
    for other, name in names.items():
        if other != kind:
            assert stats[name] == 0, (name, stats[name])
    if kind in ("early", "stale"):
        assert stats["lidar_bad_time_points"] == stats[names[kind]]
    # tracking went on: (nearly) every frame during and after the fault detected the UAV
    assert stats.get("frames_skipped", 0) <= 2, stats.get("frames_skipped")
    dets = RecordingReader(rec).records("detections")
    t = np.array([d["t_ns"] for d in dets])
    assert np.all(np.diff(t) == 100_000_000)           # every frame, in order
    detected = np.array([d["detected"] for d in dets])
    during = detected[t >= 2.9e9]                     # the fault starts 3 s into the lidar's stream
    assert len(during) >= 25 and during.mean() >= 0.9, (len(during), np.flatnonzero(~detected))
    # what was recorded is the real stream: each point once (a duplicate recorded twice as many), in order
    for fr in RecordingReader(rec).points():
        assert np.all(np.diff(fr.t_ns_points) > 0), fr.frame_index
