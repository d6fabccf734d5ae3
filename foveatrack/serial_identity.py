"""Which device a serial path names, so that a reconnecting driver only ever reopens its own head.

A head's link can vanish (an unplugged adapter, a killed head server) and its path be taken by
something else: ``/dev/ttyUSB0`` re-enumerated as another adapter, a pty number handed to another
program while a symlink still names it.  Writing Pelco bytes there drives (or corrupts) a device
that is not the head.  So the path is resolved once at start and the device remembered:

* the **node**: the real path and ``(st_rdev, st_ctime_ns)`` of the device node -- udev (devtmpfs)
  and devpts make a new node, with a new change time, whenever a device or pty appears;
* the **USB serial number** of the adapter, where there is one (sysfs), and a
  ``/dev/serial/by-id/`` name for it (udev names adapters there by vendor, model and serial);
* the **configured symlink** itself, if the path is one (``st_ino, st_mtime_ns`` from ``lstat``).

:func:`refusal` says why a reopen must be refused, or None:

* same USB serial number -> the same adapter (even re-enumerated as another ttyUSB); a different
  one -> refused;
* otherwise, a configured symlink that was re-created since (udev's by-id link of a replugged
  adapter, ``gimbal serve --link`` restarted) names the head anew -> accepted; the same old link
  whose target node is a new device -> refused (the fault: a stale link to a reused pty number);
* a plain device path whose node changed, with no serial number to prove it is the same adapter ->
  refused (give the ``/dev/serial/by-id/`` name instead).

URLs (``socket://``, ``rfc2217://``) name a server, not a device: no identity, never refused.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

BY_ID_DIR = "/dev/serial/by-id"


@dataclass(frozen=True)
class SerialIdentity:
    configured: str
    realpath: str
    node: tuple[int, int]               # (st_rdev, st_ctime_ns) of the device node
    link: tuple[int, int] | None        # (st_ino, st_mtime_ns) of the configured path if a symlink
    usb_serial: str | None
    by_id: str | None                   # a /dev/serial/by-id/ name of the same device

    def describe(self) -> str:
        extra = [f"USB serial {self.usb_serial}"] if self.usb_serial else []
        if self.by_id and self.by_id != self.configured:
            extra.append(f"by-id {self.by_id}")
        via = f"{self.configured} -> {self.realpath}" if self.realpath != self.configured else self.configured
        return via + (f" ({', '.join(extra)})" if extra else "")


def is_url(port: str) -> bool:
    return "://" in port


def _usb_serial(realpath: str) -> str | None:
    """The USB serial number of the adapter behind ``/dev/ttyUSB0`` & co (sysfs), or None."""
    dev = Path("/sys/class/tty") / os.path.basename(realpath) / "device"
    try:
        d = dev.resolve(strict=True)
    except OSError:
        return None
    for parent in [d, *d.parents]:
        if (parent / "idVendor").is_file():
            try:
                return (parent / "serial").read_text().strip() or None
            except OSError:
                return None
    return None


def _by_id(realpath: str, by_id_dir: str = BY_ID_DIR) -> str | None:
    try:
        names = sorted(os.listdir(by_id_dir))
    except OSError:
        return None
    for n in names:
        p = os.path.join(by_id_dir, n)
        if os.path.realpath(p) == realpath:
            return p
    return None


def identify(port: str, by_id_dir: str = BY_ID_DIR) -> SerialIdentity | None:
    """The identity of the device ``port`` names now; None for a URL or a path that does not exist."""
    if is_url(port):
        return None
    try:
        lst = os.lstat(port)
        real = os.path.realpath(port)
        st = os.stat(real)
    except OSError:
        return None
    link = (lst.st_ino, lst.st_mtime_ns) if os.path.islink(port) else None
    return SerialIdentity(port, real, (st.st_rdev, st.st_ctime_ns), link, _usb_serial(real),
                          _by_id(real, by_id_dir))


def refusal(first: SerialIdentity, port: str, by_id_dir: str = BY_ID_DIR) -> str | None:
    """Why reopening ``port`` must be refused (a different device holds it now), or None."""
    now = identify(port, by_id_dir)
    if now is None:
        return None          # nothing there: the open fails by itself
    what = f"the head was {first.describe()}; {port} now names {now.describe()}"
    if first.usb_serial and now.usb_serial:
        return None if first.usb_serial == now.usb_serial else f"another USB adapter holds the path: {what}"
    if now.node == first.node and now.realpath == first.realpath:
        return None
    if first.link is not None and now.link is not None and now.link != first.link:
        return None          # the link was re-created (udev by-id, a restarted head server): it names the head
    if first.link is not None:
        return (f"another device took the device the link still names (the link was not re-created): {what}; "
                "not writing to it")
    return (f"the device node was replaced and nothing proves it is the same adapter: {what}; "
            f"give [head] port as a {BY_ID_DIR}/ name (by USB serial number) to follow a replugged adapter")


class ReopenGuard:
    """``open_guard`` for :class:`gimbal.client.HeadClient`: refuses a reopen of ``path`` that finds
    another device (:func:`refusal`), and remembers the device of each reopen it allows (so a link
    re-created once is the reference for the next outage)."""

    def __init__(self, identity: SerialIdentity, path: str, by_id_dir: str = BY_ID_DIR):
        self.identity, self.path, self.by_id_dir = identity, path, by_id_dir

    def __call__(self) -> str | None:
        why = refusal(self.identity, self.path, self.by_id_dir)
        if why is None:
            self.identity = identify(self.path, self.by_id_dir) or self.identity
        return why
