"""The head link's identity (issue 16, fault 3): a reopen that finds another device is refused."""

import os
import time

import pytest

from foveatrack.serial_identity import ReopenGuard, identify, refusal

pytestmark = pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs a pty")


def _pty():
    m, s = os.openpty()
    return m, s, os.ttyname(s)


def test_a_stale_link_to_a_reused_pty_is_refused_and_a_recreated_link_accepted(tmp_path):
    m1, s1, name1 = _pty()
    link = tmp_path / "head"
    os.symlink(name1, link)
    first = identify(str(link))
    assert first.realpath == name1 and first.link is not None and first.usb_serial is None
    assert refusal(first, str(link)) is None                  # the same device: reopen
    # the head's pty goes away; the next pty (the lowest free number) is most likely the same name
    os.close(m1), os.close(s1)
    time.sleep(0.05)     # node times tick in jiffies: a pty re-made within one tick is not told apart
    held, got = [], None
    for _ in range(64):
        m, s, name = _pty()
        held.append((m, s))
        if name == name1:
            got = name
            break
    try:
        if got is None:
            pytest.skip("the pty number was not reused (other programs hold ptys)")
        why = refusal(first, str(link))
        assert why is not None and "not re-created" in why and name1 in why
        # the head's server comes back and re-creates its link (to any pty): that is the head again
        m2, s2, name2 = _pty()
        held.append((m2, s2))
        time.sleep(0.01)
        tmp = tmp_path / "head.tmp"
        os.symlink(name2, tmp)
        os.replace(tmp, link)
        g = ReopenGuard(first, str(link))
        assert g() is None and g.identity.realpath == name2
        # and the new link is the reference from now on
        assert g.identity.link != first.link
    finally:
        for m, s in held:
            os.close(m), os.close(s)


def test_a_plain_device_path_whose_node_changed_is_refused_and_urls_are_never(tmp_path):
    m1, s1, name1 = _pty()
    first = identify(name1)
    assert first.link is None
    os.close(m1), os.close(s1)
    time.sleep(0.05)
    held = []
    try:
        for _ in range(64):
            m, s, name = _pty()
            held.append((m, s))
            if name == name1:
                break
        else:
            pytest.skip("the pty number was not reused")
        why = refusal(first, name1)
        assert why is not None and "/dev/serial/by-id" in why
    finally:
        for m, s in held:
            os.close(m), os.close(s)
    assert identify("socket://127.0.0.1:9") is None
    assert identify(str(tmp_path / "absent")) is None
