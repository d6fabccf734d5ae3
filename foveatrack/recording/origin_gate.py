"""The live view's Origin check: a loopback TCP gate in front of the Foxglove SDK's WebSocket server.

A browser lets any web page open a WebSocket to ``ws://127.0.0.1:PORT`` and read what comes back;
only the handshake's ``Origin`` header says which page asked.  The SDK's ``start_server`` (0.30)
has no hook on the handshake, so the SDK serves on a free loopback port and this gate takes the
port the user named: it reads each connection's HTTP upgrade request, refuses it with ``403`` when
its ``Origin`` is not allowed, and otherwise hands the request and every byte after it, both ways,
to the SDK's server unchanged.

Allowed: a request without ``Origin`` (Foxglove's desktop app, scripts: not a web page), the origin
of Foxglove's web app (:data:`FOXGLOVE_WEB_ORIGIN`), and the origins given (``--live-origin``; ``*``
allows any).  Loopback only, on both sides.
"""

from __future__ import annotations

import ipaddress
import select
import socket
import threading

FOXGLOVE_WEB_ORIGIN = "https://app.foxglove.dev"
MAX_REQUEST_BYTES = 16 * 1024      # an upgrade request is a few hundred bytes; more is not one
REQUEST_TIMEOUT_S = 5.0            # a connection that does not finish its request by then is closed


def normalise_origin(origin: str) -> str:
    """An origin as compared: lower case, no trailing slash (``scheme://host[:port]``)."""
    return origin.strip().rstrip("/").lower()


def request_origin(request: bytes) -> str | None:
    """The ``Origin`` header of an HTTP request head (None: it has none)."""
    for line in request.split(b"\r\n")[1:]:
        name, sep, value = line.partition(b":")
        if sep and name.strip().lower() == b"origin":
            return value.strip().decode("latin-1")
    return None


class OriginGate:
    """Listen on ``host:port`` (loopback; port 0: any free one) and forward connections whose
    handshake ``Origin`` is allowed to ``host:upstream_port``.  ``port`` is the bound port;
    ``refused`` lists the origins refused (each once); ``on_refused(origin)`` is called the first
    time an origin is refused.  ``stop()`` closes the port and every forwarded connection."""

    def __init__(self, host: str, port: int, upstream_port: int, allowed_origins=(), on_refused=None):
        if not ipaddress.ip_address(host).is_loopback:
            raise ValueError(f"the live view's gate serves loopback only, not {host!r}")
        allowed = {normalise_origin(o) for o in allowed_origins}
        self.allow_any = "*" in allowed
        self.allowed = allowed | {FOXGLOVE_WEB_ORIGIN}
        self.host, self.upstream = host, (host, int(upstream_port))
        self.on_refused = on_refused
        self.refused: list[str] = []
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self._sock = socket.socket(family, socket.SOCK_STREAM)
        self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self._sock.bind((host, int(port)))
            self._sock.listen(16)
        except OSError:
            self._sock.close()
            raise
        self.port = self._sock.getsockname()[1]
        self._sock.settimeout(0.25)     # accept() wakes to see stop()
        self._lock = threading.Lock()
        self._open: set[socket.socket] = set()
        self._stopping = False
        self._thread = threading.Thread(target=self._accept_loop, name="live-origin-gate", daemon=True)
        self._thread.start()

    def allows(self, origin: str | None) -> bool:
        return origin is None or self.allow_any or normalise_origin(origin) in self.allowed

    def _accept_loop(self) -> None:
        while not self._stopping:
            try:
                conn, _addr = self._sock.accept()
            except TimeoutError:
                continue
            except OSError:
                return          # closed by stop()
            if self._stopping:
                conn.close()
                return
            threading.Thread(target=self._serve, args=(conn,), name="live-origin-conn", daemon=True).start()

    def _track(self, *socks) -> bool:
        with self._lock:
            if self._stopping:
                return False
            self._open.update(socks)
            return True

    def _untrack(self, *socks) -> None:
        with self._lock:
            for s in socks:
                self._open.discard(s)
        for s in socks:
            try:
                s.close()
            except OSError:
                pass

    def _serve(self, conn: socket.socket) -> None:
        up = None
        if not self._track(conn):
            conn.close()
            return
        try:
            conn.settimeout(REQUEST_TIMEOUT_S)
            head = b""
            while b"\r\n\r\n" not in head:
                if len(head) > MAX_REQUEST_BYTES:
                    return
                b = conn.recv(4096)
                if not b:
                    return
                head += b
            origin = request_origin(head.split(b"\r\n\r\n", 1)[0])
            if not self.allows(origin):
                # said before the 403 goes out: whoever saw the refusal can find the line that explains it
                with self._lock:
                    first = origin not in self.refused
                    if first:
                        self.refused.append(origin)
                if first and self.on_refused is not None:
                    self.on_refused(origin)
                body = b"Origin not allowed by the live view (foveatrack --live-origin)\n"
                conn.sendall(b"HTTP/1.1 403 Forbidden\r\nContent-Type: text/plain\r\nContent-Length: "
                             + str(len(body)).encode() + b"\r\nConnection: close\r\n\r\n" + body)
                return
            conn.settimeout(None)
            up = socket.create_connection(self.upstream, timeout=REQUEST_TIMEOUT_S)
            up.settimeout(None)
            if not self._track(up):
                return
            up.sendall(head)
            self._pump(conn, up)
        except (OSError, ValueError):     # a peer gone, or stop() closed the sockets under the pump
            pass
        finally:
            self._untrack(*(s for s in (conn, up) if s is not None))

    @staticmethod
    def _pump(a: socket.socket, b: socket.socket) -> None:
        """Bytes both ways until either side closes."""
        peer = {a: b, b: a}
        while True:
            ready, _, _ = select.select([a, b], [], [])
            for s in ready:
                data = s.recv(65536)
                if not data:
                    return
                peer[s].sendall(data)

    def stop(self) -> None:
        with self._lock:
            self._stopping = True
            socks = list(self._open)
            self._open.clear()
        try:
            self._sock.close()
        except OSError:
            pass
        for s in socks:
            try:
                s.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            try:
                s.close()
            except OSError:
                pass
        self._thread.join(timeout=2.0)
