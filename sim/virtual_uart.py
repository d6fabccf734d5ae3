"""A UART line in virtual time: bytes take 10 bits / baud each (8N1), with optional effects.

One :class:`VirtualUart` carries one direction (host -> head, or head -> host).  A byte handed to
:meth:`VirtualUart.send` at ``t_s`` starts on the wire when the line is free (behind bytes still
being sent) and arrives when its stop bit ends, so a 7-byte Pelco-D frame takes 7.29 ms at 9600 baud
(facts file, "UART timing").

Effects a scene can ask for (names in ``effects``):

* ``'bit_errors'``: each data bit flips with probability ``bit_error_rate``;
* ``'drop'``: each byte is lost with probability ``drop_rate`` (it still occupies the wire);
* ``'echo'``: RS-485 half duplex with the receiver always on: the sender hears its own bytes, at
  the times they finish on the wire; collect them with :meth:`VirtualUart.pop_echo`.

Randomness: each random effect draws from its own stream (``rngs``, one Generator per effect; or
one ``rng`` from which a child stream is spawned for each of 'bit_errors' and 'drop', both always,
in that order).  An effect that is not enabled draws no random numbers, and no effect draws from
another's stream, so enabling one effect never changes another's draws.
Time is always an argument; nothing here reads a clock.
"""

from __future__ import annotations

import numpy as np

from gimbal.pelco import BITS_PER_BYTE  # 8N1: the link's facts live with the protocol

EFFECTS = frozenset({"bit_errors", "drop", "echo"})
_RANDOM_EFFECTS = frozenset({"bit_errors", "drop"})
_BYTE = [bytes((b,)) for b in range(256)]


class VirtualUart:
    """One direction of a serial line in virtual time.

    baud : int > 0 [bit/s]
    effects : subset of {'bit_errors', 'drop', 'echo'}
    rng : numpy Generator, from which each random effect's stream is spawned (module docstring)
    rngs : {'bit_errors': Generator, 'drop': Generator}, each random effect's own stream (instead of
        ``rng``); one of the two is required when 'bit_errors' or 'drop' is enabled
    bit_error_rate : probability in [0, 1] per data bit ('bit_errors')
    drop_rate : probability in [0, 1] per byte ('drop')
    echo : bool, same as putting 'echo' in effects
    """

    def __init__(
        self,
        baud: int = 9600,
        effects: frozenset[str] | set[str] | tuple = frozenset(),
        rng: np.random.Generator | None = None,
        bit_error_rate: float = 1e-4,
        drop_rate: float = 1e-3,
        echo: bool = False,
        rngs: dict[str, np.random.Generator] | None = None,
    ) -> None:
        effects = frozenset(effects)
        unknown = effects - EFFECTS
        if unknown:
            raise ValueError(f"unknown UART effects {sorted(unknown)}; allowed {sorted(EFFECTS)}")
        if not baud > 0:
            raise ValueError(f"baud={baud!r} must be > 0")
        if not 0 <= bit_error_rate <= 1 or not 0 <= drop_rate <= 1:
            raise ValueError("bit_error_rate and drop_rate must be probabilities in [0, 1]")
        if echo:
            effects = effects | {"echo"}
        if rng is not None and rngs is not None:
            raise ValueError("give either rng (one stream, spawned per effect) or rngs (one per effect)")
        if rng is not None and effects & _RANDOM_EFFECTS:   # (spawning draws nothing from rng)
            rngs = dict(zip(("bit_errors", "drop"), rng.spawn(2)))
        rngs = dict(rngs or {})
        missing = sorted(e for e in effects & _RANDOM_EFFECTS if e not in rngs)
        if missing:
            raise ValueError(f"UART effects {missing} need an rng (numpy Generator), or their own in rngs")
        self.baud = baud
        self.effects = effects
        self.rngs = rngs
        self.bit_error_rate = float(bit_error_rate)
        self.drop_rate = float(drop_rate)
        self._line_free_s = -np.inf
        self._echo: list[tuple[float, bytes]] = []
        self.bytes_sent = 0
        self.bytes_dropped = 0
        self.bits_flipped = 0

    @property
    def byte_time_s(self) -> float:
        """Duration of one byte on the wire [s] (10 bits / baud)."""
        return BITS_PER_BYTE / self.baud

    @property
    def line_free_at_s(self) -> float:
        """Virtual time the last byte handed in finishes on the wire."""
        return self._line_free_s

    def send(self, data: bytes, t_s: float) -> list[tuple[float, bytes]]:
        """Put ``data`` on the line at ``t_s``; return ``(arrival_time_s, byte)`` per delivered byte.

        Bytes are serialised behind earlier bytes still on the wire; arrival = end of stop bit.
        Dropped bytes are absent from the result; flipped bits are applied.
        """
        data = bytes(data)
        n = len(data)
        if n == 0:
            return []
        start = max(float(t_s), self._line_free_s)
        if not self.effects & _RANDOM_EFFECTS:
            # No random effect: plain Python floats, the numpy route's arithmetic element by element
            # (start + byte_time * k), so the same times to the bit; no numpy calls on 7 bytes.
            bt = self.byte_time_s
            ends = [start + bt * k for k in range(1, n + 1)]
            self._line_free_s = ends[-1]
            self.bytes_sent += n
            out = [(t, _BYTE[b]) for t, b in zip(ends, data)]
            if "echo" in self.effects:
                self._echo.extend(out)
            return out
        ends = start + self.byte_time_s * np.arange(1, n + 1)
        self._line_free_s = float(ends[-1])
        self.bytes_sent += n
        if "echo" in self.effects:
            self._echo.extend((float(t), bytes((b,))) for t, b in zip(ends, data))
        out = np.frombuffer(data, dtype=np.uint8).copy()
        if "bit_errors" in self.effects:
            flips = self.rngs["bit_errors"].random((n, 8)) < self.bit_error_rate
            out ^= (flips * (1 << np.arange(8))).sum(axis=1).astype(np.uint8)
            self.bits_flipped += int(flips.sum())
        keep = np.ones(n, dtype=bool)
        if "drop" in self.effects:
            keep = self.rngs["drop"].random(n) >= self.drop_rate
            self.bytes_dropped += int(n - keep.sum())
        return [(float(t), bytes((int(b),))) for t, b, k in zip(ends, out, keep) if k]

    def pop_echo(self) -> list[tuple[float, bytes]]:
        """The sender's own bytes heard back ('echo' effect), oldest first; clears them."""
        out, self._echo = self._echo, []
        return out


def join_arrivals(arrivals: list[tuple[float, bytes]]) -> tuple[bytes, list[float]]:
    """Concatenate per-byte arrivals into ``(data, per_byte_times)`` for ``receive``/``feed``."""
    data = b"".join(b for _, b in arrivals)
    times = [t for t, b in arrivals for _ in b]
    return data, times
