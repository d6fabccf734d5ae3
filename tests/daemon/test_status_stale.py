"""The status line when frames stop (the lidar went silent): no rate, points or error of the last
frame shown as the present's (a user watched '10.0 Hz 3381 pts/frame' for 8 s after the lidar died)."""

from types import SimpleNamespace

from foveatrack.daemon.status_display import STALE_STATUS_S, StatusDisplay


def _display(shown):
    d = StatusDisplay()
    d.last_out = SimpleNamespace(state=SimpleNamespace(value="tracking"), error_pan_deg=-2.0, error_tilt_deg=2.0)
    d.last_pts = 3381
    d.pose_state = None
    d.head = SimpleNamespace(refused=False, connected=True)
    d.lat_ms = SimpleNamespace(last=18.0)
    d.drops = lambda: 0
    d.status = SimpleNamespace(show=shown.append)
    d.status_notes = lambda: []
    return d


def test_the_status_line_drops_the_last_frames_figures_once_frames_stop():
    shown = []
    d = _display(shown)
    times = [100.0 + 0.1 * k for k in range(11)]          # 10 Hz until t = 101.0
    d._show_status(times, False, now=101.05)
    assert "10.0 Hz" in shown[-1] and "3381 pts/frame" in shown[-1] and "-2.0/ +2.0" in shown[-1]
    d._show_status(times, True, now=101.0 + STALE_STATUS_S + 0.5)
    assert " 0.0 Hz" in shown[-1] and "     0 pts/frame" in shown[-1] and "-/-" in shown[-1], shown[-1]
    assert "watchdog" in shown[-1]
