"""``Daemon.run`` puts back the SIGINT/SIGTERM handlers it found on every way out, also when a step of
its start or its shutdown raises.  (They were installed before the run's ``try`` and put back only at
the end of the shutdown, after steps that can raise: a daemon run in-process then left its handler
behind, and a later Ctrl-C in that process only set the event of a daemon long gone.)"""

import signal

import pytest

from daemon_procs import loop_head_daemon


def _daemon(tmp_path):
    # no lidar answers: the run ends after duration_s
    return loop_head_daemon(tmp_path, log_path=str(tmp_path / "d.jsonl"), duration_s=0.3, install_signals=True)


def _callers_int(signum, frame):    # the handlers the caller had: distinct from Python's own
    pass


def _callers_term(signum, frame):
    pass


@pytest.fixture
def callers_handlers():
    old = {signal.SIGINT: signal.signal(signal.SIGINT, _callers_int),
           signal.SIGTERM: signal.signal(signal.SIGTERM, _callers_term)}
    yield
    for sig, h in old.items():
        signal.signal(sig, h)


def _handlers():
    return signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)


def test_a_run_puts_the_handlers_back(tmp_path, callers_handlers):
    d = _daemon(tmp_path)
    seen = []
    real_event = d.log.event
    d.log.event = lambda name, **kw: (seen.append(_handlers()) if name == "stop" else None, real_event(name, **kw))
    assert d.run() == 0
    assert seen and seen[0][0] is not _callers_int and seen[0][1] is not _callers_term   # its own while it ran
    assert _handlers() == (_callers_int, _callers_term)


@pytest.mark.parametrize("step", ["start event", "status.done", "log.close", "recorder.close"])
def test_a_step_that_raises_still_puts_the_handlers_back(tmp_path, callers_handlers, monkeypatch, step):
    d = _daemon(tmp_path)
    seen, planted = [], []

    def boom(*args, **kwargs):
        seen.append(_handlers())
        raise RuntimeError(f"planted in {step}")

    if step == "start event":
        real_event = d.log.event
        d.log.event = lambda name, **kw: boom() if name == "start" else real_event(name, **kw)
    elif step == "recorder.close":
        real_open = d._open

        def open_then_plant():
            real_open()
            planted.append(d.recorder.close)
            d.recorder.close = boom
        d._open = open_then_plant
    else:
        obj, name = step.split(".")
        setattr(getattr(d, obj), name, boom)
    try:
        with pytest.raises(RuntimeError, match="planted"):
            d.run()
    finally:
        for close in planted:   # the recording's writer thread, which the planted close left running
            close()
    assert seen and seen[0] != (_callers_int, _callers_term)      # the daemon's own were in place
    assert _handlers() == (_callers_int, _callers_term)
