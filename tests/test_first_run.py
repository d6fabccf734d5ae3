"""A first run is honest: a slow first frame (the numba compile) is announced and kept out of the
progress bar, and the stage timings exclude it."""

import io
import threading

from foveatrack.cli.simulate_cmd import CompileNotice


def test_a_slow_first_frame_is_announced_and_timed():
    out = io.StringIO()
    notice = CompileNotice(after_s=0.01, stream=out)
    threading.Event().wait(0.3)   # a first frame still compiling after after_s
    notice.done()
    notice.done()                 # a second call says nothing more
    lines = out.getvalue().splitlines()
    assert lines[0] == CompileNotice.MESSAGE and "about a minute" in lines[0] and "warmup" in lines[0]
    assert lines[1].startswith("kernels ready after ") and len(lines) == 2


def test_a_fast_first_frame_says_nothing():
    out = io.StringIO()
    notice = CompileNotice(after_s=5.0, stream=out)
    notice.done()
    threading.Event().wait(0.05)
    assert out.getvalue() == ""
    silent = CompileNotice(enabled=False, after_s=0.0, stream=out)
    threading.Event().wait(0.05)
    silent.done()
    assert out.getvalue() == ""
