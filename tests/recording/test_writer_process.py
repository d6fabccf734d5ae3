"""The recording written from a child process (foveatrack.recording.writer_process): the same file
as the loop's-thread writer, errors raised in the caller, nothing lost when the caller dies."""

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from child_procs import dies_with_this_process
from foveatrack.errors import UserError
from foveatrack.recording import RecordingExistsError, RecordingReader, RecordingWriter
from foveatrack.recording.writer_process import RecordingProcess

ROOT = Path(__file__).resolve().parents[2]
META = {"scene_toml": "[scene]\nname = 'x'\n", "seed": 42}


def frames(n_frames=6, n_points=300, seed=0):
    rng = np.random.default_rng(seed)
    for k in range(n_frames):
        t = 1_000_000_000 + k * 100_000_000
        # on the Livox mm grid for even frames (stored compactly), off it for odd ones (float64)
        xyz = rng.normal(0, 30, (n_points, 3))
        if k % 2 == 0:
            xyz = np.rint(xyz * 1000).astype(np.int32) * 1e-3
        tp = t - 100_000_000 + np.sort(rng.integers(0, 10_000, n_points)) * 10_000
        yield k, t, xyz, tp, rng.integers(0, 256, n_points).astype(np.uint8)


def write_all(w):
    for k, t, xyz, tp, refl in frames():
        if k == 3:      # a frame without points (the lidar saw nothing)
            xyz, tp, refl = xyz[:0], tp[:0], refl[:0]
        w.write_points(t, k, xyz, tp, refl)
        w.write_detection(t, k, len(xyz) > 0, xyz_m=xyz.mean(0) if len(xyz) else None, n_points=len(xyz))
        w.write_command(t + 500, b"\xff\x01\x00\x04\x20\x00\x25", frame_id=k)
        w.write_head_estimate(t, pan_deg=0.1 * k, tilt_deg=-0.2 * k, world_xyz_m=[10.0, k, 2.0])
        w.write_truth(t, pan_deg=0.1 * k, tilt_deg=0.0, target_xyz_m=[10.0, k, 2.0])
        w.write_metric(t, "proc_ms", 1.5 + k)
        if k == 2:
            w.flush()


def test_the_child_writes_the_same_file_to_the_byte(tmp_path):
    with RecordingWriter(tmp_path / "thread.mcap", META, created_utc="fixed") as w:
        write_all(w)
    with RecordingProcess().open(tmp_path / "process.mcap", META, created_utc="fixed") as w:
        write_all(w)
        assert (w.frames_written, w.messages_written) == (6, 36)
    assert (tmp_path / "process.mcap").read_bytes() == (tmp_path / "thread.mcap").read_bytes()


@pytest.mark.slow
def test_a_simulated_run_records_the_same_file_either_way(tmp_path):
    # what simulate --out does (child process) and simulate --one-thread does (loop's thread)
    from foveatrack.cli.simulate_cmd import run_and_report

    sums = {}
    for name, proc in (("child", True), ("loop", False)):
        sums[name] = run_and_report(ROOT / "scenes" / "fig12-tracking.toml", tmp_path / name, quiet=True,
                                    progress=False, duration=1.5, recording_process=proc, ahead=False)
    assert sums["child"]["recording_written_by"] == "a child process"
    assert sums["loop"]["recording_written_by"] == "the loop's thread"
    a, b = ((tmp_path / n / "run.mcap").read_bytes() for n in ("child", "loop"))
    assert a == b
    assert len(list(RecordingReader(tmp_path / "child" / "run.mcap").points())) == 15


def test_arrays_may_change_once_a_call_returns(tmp_path):
    (k, t, xyz, tp, refl), = frames(1)
    keep = xyz.copy()
    with RecordingProcess().open(tmp_path / "r.mcap", META) as w:
        w.write_points(t, k, xyz, tp, refl)
        xyz[:] = 0.0        # the kernel has the bytes: changing the caller's array changes nothing
    got, = RecordingReader(tmp_path / "r.mcap").points()
    assert np.array_equal(got.xyz, keep)


def test_wrong_options_are_errors_at_once(tmp_path):
    p = tmp_path / "exists.mcap"
    p.write_bytes(b"x")
    with RecordingProcess() as w:
        with pytest.raises(RecordingExistsError, match="exists.mcap already exists"):
            w.open(p, META)
        with pytest.raises(UserError, match="compression 'brotli'"):
            w.open(tmp_path / "a.mcap", META, compression="brotli")
        with pytest.raises(ValueError, match="open"):
            w.write_metric(0, "x", 1.0)
    assert p.read_bytes() == b"x"


def test_an_error_in_the_child_is_raised_in_the_caller_and_the_file_is_completed(tmp_path):
    p = tmp_path / "r.mcap"
    w = RecordingProcess().open(p, META)
    (k, t, xyz, tp, refl), = frames(1)
    w.write_points(t, k, xyz, tp, refl)
    w.write_points(-5, 1, xyz, tp, refl)      # a negative log time: the child's RecordingWriter refuses it
    with pytest.raises(RuntimeError, match="recording process failed .*t_ns must be >= 0"):
        for _ in range(1000):                 # raised by a later frame or flush, once the child reported it
            w.flush()
            time.sleep(0.01)
    w.close()
    r = RecordingReader(p)
    assert [f.frame_index for f in r.points()] == [0]
    assert r.complete


def test_a_child_that_dies_is_reported(tmp_path):
    w = RecordingProcess().open(tmp_path / "r.mcap", META)
    w.wait_ready()
    w._proc.send_signal(signal.SIGKILL)
    w._proc.wait(10)
    (k, t, xyz, tp, refl), = frames(1, n_points=100_000)     # more than the pipe holds
    with pytest.raises(RuntimeError, match="recording process ended early"):
        w.write_points(t, k, xyz, tp, refl)
    with pytest.raises(RuntimeError, match="exited with code -9"):
        w.close()


def test_ctrl_c_at_the_terminal_does_not_stop_the_child(tmp_path):
    p = tmp_path / "r.mcap"
    with RecordingProcess().open(p, META) as w:
        w.wait_ready()
        w._proc.send_signal(signal.SIGINT)     # what the terminal sends to the whole process group
        w._proc.send_signal(signal.SIGTERM)
        write_all(w)
    r = RecordingReader(p)
    assert len(list(r.points())) == 6
    assert r.complete


def test_a_ctrl_c_in_the_middle_of_a_message_loses_only_that_message(tmp_path, monkeypatch):
    # A signal can cut a write to a full pipe short, and the KeyboardInterrupt then lands with part of
    # a message in the pipe.  Anything sent after it would be read as its rest (the child choked on
    # it, and left the file without its summary): close() must end the pipe and send nothing more.
    p = tmp_path / "r.mcap"
    real_writev = os.writev
    messages = []

    def cut_short(fd, views):
        messages.append(fd)
        if len(messages) == 3:      # the points of frame 2 (with the rest of frame 1)
            data = b"".join(bytes(v) for v in views)
            os.write(fd, data[:-8])             # all of it in the pipe but its last 8 bytes ...
            raise KeyboardInterrupt             # ... when the Ctrl-C lands
        return real_writev(fd, views)

    w = RecordingProcess().open(p, META)
    monkeypatch.setattr(os, "writev", cut_short)
    with pytest.raises(KeyboardInterrupt):
        write_all(w)
    with pytest.raises(RuntimeError, match="cut short"):
        w.flush()           # nothing more may go after a cut message but the end of the pipe
    w.close()
    monkeypatch.undo()
    assert w._proc.returncode == 0
    r = RecordingReader(p)
    assert [f.frame_index for f in r.points()] == [0, 1]      # frame 2's message was cut: dropped whole
    assert r.complete, r.problem
    assert [m["value"] for m in r.records("metrics")] == [1.5]   # frame 1's went with frame 2's points


def test_an_unopened_child_ends_at_once_with_its_caller():
    # simulate starts the child before it reads the scene: a wrong scene must not wait for its start
    w = RecordingProcess()
    w.close()
    assert w._proc.returncode == -signal.SIGKILL    # ended, not waited for until its start was done


CALLER = textwrap.dedent(
    """
    import sys, numpy as np
    sys.path.insert(0, {root!r})
    from foveatrack.recording.writer_process import RecordingProcess
    w = RecordingProcess().open(sys.argv[1], {{"seed": 1}})
    for k in range(10):
        xyz = np.full((50, 3), float(k))
        w.write_points(10**9 + k * 10**8, k, xyz, np.full(50, 10**9 + k * 10**8, np.int64), np.zeros(50, np.uint8))
        w.write_metric(10**9 + k * 10**8, "k", k)
    w.flush()
    print(w._proc.pid, flush=True)
    sys.stdin.readline()
    """
)


# A Ctrl-C lands in the caller's thread at any bytecode boundary (the signal handler runs between two
# instructions), and where the child is behind, mostly in the ring's wait for it (_wait_for_child).
# That wait once asked Popen.poll() whether the child still ran; poll() takes the Popen's lock with a
# bare acquire() before its try, so a KeyboardInterrupt just after the acquire left the lock taken,
# and close()'s wait for the child blocked on it for ever (the SIGINT test below hung;
# docs/interrupts.md).  This child process raises KeyboardInterrupt at the n-th instruction of one
# round of that wait (callees included), for every n until the round ends by itself, and checks after
# each that close() still ends (within 20 s, in a helper thread).
INTERRUPTED_WAIT = textwrap.dedent(
    """
    import os, sys, threading
    sys.path.insert(0, {root!r})
    from foveatrack.recording.writer_process import RecordingProcess

    def interrupt_at(n):
        count = [0]
        def tracer(frame, event, arg):
            frame.f_trace_opcodes = True
            if event == "opcode":
                count[0] += 1
                if count[0] == n:
                    sys.settrace(None)
                    raise KeyboardInterrupt(f"{{frame.f_code.co_filename}}:{{frame.f_lineno}}")
            return tracer
        return tracer

    cases = 0
    for n in range(1, 10_000):
        w = RecordingProcess()      # unopened: close() ends the child at once and waits for it
        sys.settrace(interrupt_at(n))
        try:
            w._wait_for_child()
            hit = False
        except KeyboardInterrupt:
            hit = True
        finally:
            sys.settrace(None)
        closer = threading.Thread(target=w.close, daemon=True)
        closer.start()
        closer.join(20)
        if closer.is_alive():
            print("HANG", n, flush=True)
            os._exit(3)
        if not hit:         # n is past the wait's last instruction: every one was tried
            break
        cases += 1
    print("ok", cases, flush=True)
    """
)


def test_a_ctrl_c_at_any_instruction_of_the_wait_for_the_child_leaves_close_able_to_end():
    p = subprocess.run([sys.executable, "-c", INTERRUPTED_WAIT.format(root=str(ROOT))], capture_output=True,
                       text=True, timeout=600)
    assert p.returncode == 0 and "HANG" not in p.stdout, p.stdout + p.stderr
    assert int(p.stdout.split()[-1]) >= 10      # the wait was interrupted at each of its instructions


@pytest.mark.slow
def test_kill_9_of_the_caller_loses_nothing_the_child_got(tmp_path):
    # the child reads to the end of the pipe and completes the file (the loop's-thread writer would
    # leave it readable only up to its last chunk)
    p = tmp_path / "killed.mcap"
    caller = subprocess.Popen(dies_with_this_process([sys.executable, "-c", CALLER.format(root=str(ROOT)), str(p)]),
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    child_pid = int(caller.stdout.readline())
    caller.send_signal(signal.SIGKILL)
    caller.wait(10)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:      # the child is not ours to wait for: poll until it is gone
        try:
            os.kill(child_pid, 0)
        except ProcessLookupError:
            break
        time.sleep(0.05)
    else:
        pytest.fail("the writer process did not end after its caller was killed")
    r = RecordingReader(p)
    assert [f.frame_index for f in r.points()] == list(range(10))
    assert r.complete
    assert [m["value"] for m in r.records("metrics")] == list(range(10))


def test_simulate_uses_a_second_core_only_where_one_is_free():
    from foveatrack.cli.simulate_cmd import _others_running, core_free

    assert core_free(load_1min=0.7, others_running=0, cores=2)      # an earlier run of ours: still free
    assert not core_free(load_1min=0.7, others_running=1, cores=2)  # another task holds the other core
    assert not core_free(load_1min=2.5, others_running=0, cores=2)  # a job between its processes
    assert not core_free(load_1min=0.0, others_running=0, cores=1)
    assert core_free(load_1min=5.0, others_running=5, cores=8)
    assert not core_free(load_1min=5.0, others_running=7, cores=8)
    assert _others_running() >= 0


def test_simulate_second_core_and_one_thread_flags():
    from foveatrack.cli import build_parser
    from foveatrack.cli.simulate_cmd import _cores_flag

    p = build_parser()
    assert _cores_flag(p.parse_args(["simulate", "s.toml"])) is None
    assert _cores_flag(p.parse_args(["simulate", "s.toml", "--one-thread"])) is False
    assert _cores_flag(p.parse_args(["simulate", "s.toml", "--second-core"])) is True
    with pytest.raises(SystemExit):
        p.parse_args(["simulate", "s.toml", "--one-thread", "--second-core"])


def test_frames_wrap_the_ring_many_times_and_oversized_ones_go_by_the_pipe(tmp_path):
    # 16 MiB ring: frames of 100 k points (3.3 MB) wrap it every few frames, and the caller waits for
    # the child to read on; a 400 k-point frame (9.6 MB of xyz, over half the ring) goes by the pipe
    rng = np.random.default_rng(3)
    sent = []
    with RecordingProcess().open(tmp_path / "r.mcap", META) as w:
        for k, n in enumerate([100_000] * 12 + [400_000, 7, 100_000]):
            t = 10**9 + k * 10**8
            xyz = np.rint(rng.normal(0, 30_000, (n, 3))) * 1e-3      # on the mm grid
            tp = t - np.arange(n, dtype=np.int64)[::-1] * 100
            refl = rng.integers(0, 256, n).astype(np.uint8)
            w.write_points(t, k, xyz, tp, refl)
            sent.append((xyz, tp, refl))
    got = list(RecordingReader(tmp_path / "r.mcap").points())
    assert len(got) == len(sent)
    for f, (xyz, tp, refl) in zip(got, sent):
        assert np.array_equal(f.xyz, xyz) and np.array_equal(f.t_ns_points, tp)
        assert np.array_equal(f.reflectivity, refl)


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_simulate_stopped_by_a_signal_leaves_a_complete_recording(tmp_path, sig):
    # Ctrl-C (the parent closes the scan-ahead worker and the writer on its way out, and says so) or
    # SIGTERM (the parent dies at once, the child reads to the end of the pipe): either way the file
    # is complete, with every frame it holds.  (A Ctrl-C once hung here: a KeyboardInterrupt just
    # after the loop's thread took a concurrent.futures Future's lock left it taken, and the worker
    # and the exit waited on it for ever; sim/ahead.py's Job, tests/world/test_ahead.py.)
    out = tmp_path / "run"
    p = subprocess.Popen(dies_with_this_process([sys.executable, "-m", "foveatrack", "simulate",
                                                 str(ROOT / "scenes" / "fig12-tracking.toml"), "--duration", "3000",
                                                 "--out", str(out), "--second-core", "--no-progress"]),
                         stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while not ((out / "run.mcap").exists() and (out / "run.mcap").stat().st_size > 2_000_000):
            assert p.poll() is None and time.monotonic() < deadline, p.stderr.read() if p.poll() else "slow start"
            time.sleep(0.1)
        p.send_signal(sig)
        _, err = p.communicate(timeout=60)      # the end of stderr: the writer process has ended too
    finally:
        p.kill()
    if sig == signal.SIGINT:
        assert p.returncode == 130 and "foveatrack: interrupted" in err, err
    else:
        assert p.returncode == -signal.SIGTERM
    deadline = time.monotonic() + 60
    while True:     # after SIGTERM the child may still be completing the file: read until it is
        r = RecordingReader(out / "run.mcap")
        frames = [f.frame_index for f in r.points()]
        if r.complete or time.monotonic() > deadline:
            break
        time.sleep(0.2)
    assert frames and frames == list(range(len(frames)))
    assert r.complete, r.problem
