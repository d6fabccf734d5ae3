"""Pelco-D and Pelco-P: pure byte encoding and decoding (no I/O, no state).

The paper's head (Appendix D, "PTS-303H", driven over a UART; the vendor API sets each motor's
speed) belongs to a family that speaks Pelco-D and Pelco-P and answers in the envelope it received.

Frames
------
Pelco-D (7 bytes)::

    FF addr cmd1 cmd2 d1 d2 sum        sum = (addr + cmd1 + cmd2 + d1 + d2) & 0xFF

Pelco-P (8 bytes)::

    A0 addr cmd1 cmd2 d1 d2 AF xor     xor = A0 ^ addr ^ cmd1 ^ cmd2 ^ d1 ^ d2 ^ AF

cmd2 bits (both envelopes): 0x10 tilt down, 0x08 tilt up, 0x04 pan left, 0x02 pan right; they
combine, so one frame carries both axes' speeds.  d1 = pan speed 0x00-0x3F, d2 = tilt speed
0x00-0x3F.  Turbo pan is d1 = 0xFF in Pelco-D and d1 = 0x40 in Pelco-P; decoded frames report
turbo as ``pan_byte == PAN_TURBO`` (0xFF) whichever envelope carried it.  Extended commands have
cmd2 bit 0 set: 0x03 set preset, 0x05 clear preset, 0x07 go to preset (number in d2), 0x4B set
pan, 0x4D set tilt (position word in d1:d2, big-endian), 0x51 / 0x53 query pan / tilt, answered
by 0x59 / 0x5B carrying the word.

Addresses
---------
Every ``address`` in this API is the *logical* (DIP-switch) camera address.  Pelco-D sends it as
is (0-255); Pelco-P addresses are zero-based on the wire, so logical 1-256 is sent as 0-255.

Position words and the project's angle conventions
--------------------------------------------------
Word = hundredths of a degree, 0-35999.  Pan: ``pan_deg`` positive = CCW seen from above =
turning LEFT (Pelco "left" increases pan), wrapped to (-180, 180]; the pan word is
``round(pan_deg * 100) mod 36000``.  Tilt: ``tilt_deg`` positive = UP.  Pelco tilt words grow
downwards; with ``tilt_zero='level'`` the word is ``round(-tilt_deg * 100) mod 36000`` (0 = level);
the PTS family's quirk (bench notes: "the tilt word is inverted, native 0 = zenith") is
``tilt_zero='zenith'``: word = ``round((90 - tilt_deg) * 100) mod 36000``.
"""

from __future__ import annotations

import math

from dataclasses import dataclass
from functools import cached_property

from gimbal.errors import GimbalError

SYNC_D = 0xFF
STX_P = 0xA0
ETX_P = 0xAF
FRAME_LEN = {"D": 7, "P": 8}
BITS_PER_BYTE = 10  # on the wire, 8N1: start bit + 8 data bits + stop bit


def byte_time_s(baud: int) -> float:
    """One byte on the wire [s]: 10 bits (8N1) at ``baud`` [bit/s]."""
    return BITS_PER_BYTE / baud


def frame_time_s(protocol: str, baud: int) -> float:
    """One command frame on the wire [s]: 7 bytes for Pelco-D, 8 for Pelco-P, at ``baud`` (8N1).

    The time from the first byte leaving the host to the head having the whole command: the part of
    the command latency the dead reckoning adds to the send time (70 / baud for Pelco-D, 80 / baud
    for Pelco-P; 7.3 and 8.3 ms at 9600 baud).
    """
    _check_protocol(protocol)
    return FRAME_LEN[protocol] * byte_time_s(baud)

PAN_TURBO = 0xFF  # the normalised turbo pan byte (Pelco-D wire value)
_P_TURBO_WIRE = 0x40  # Pelco-P's wire value for turbo pan
MAX_SPEED_BYTE = 0x3F

# cmd2 bits
TILT_DOWN = 0x10
TILT_UP = 0x08
PAN_LEFT = 0x04
PAN_RIGHT = 0x02

# extended opcodes (cmd2, cmd1 = 0)
OP_SET_PRESET = 0x03
OP_CLEAR_PRESET = 0x05
OP_GOTO_PRESET = 0x07
OP_SET_PAN = 0x4B
OP_SET_TILT = 0x4D
OP_QUERY_PAN = 0x51
OP_QUERY_TILT = 0x53
OP_PAN_REPLY = 0x59
OP_TILT_REPLY = 0x5B

_EXT_KINDS = {
    OP_SET_PRESET: "set_preset",
    OP_CLEAR_PRESET: "clear_preset",
    OP_GOTO_PRESET: "goto_preset",
    OP_SET_PAN: "set_pan",
    OP_SET_TILT: "set_tilt",
    OP_QUERY_PAN: "query_pan",
    OP_QUERY_TILT: "query_tilt",
    OP_PAN_REPLY: "pan_reply",
    OP_TILT_REPLY: "tilt_reply",
}
KINDS = ("stop", "pan_tilt", "other", "unknown_extended") + tuple(_EXT_KINDS.values())

WORD_MODULUS = 36000  # hundredths of a degree in a turn


class PelcoDecodeError(GimbalError):
    """A byte string is not a valid Pelco frame (length, sync/ETX or checksum)."""


# --------------------------------------------------------------------------------------------
# checksums
# --------------------------------------------------------------------------------------------
def checksum_d(body: bytes | bytearray) -> int:
    """Pelco-D checksum of ``addr cmd1 cmd2 d1 d2`` (sync byte excluded): the byte sum mod 256."""
    return sum(body) & 0xFF


def checksum_p(first7: bytes | bytearray) -> int:
    """Pelco-P checksum: XOR of bytes 1-7 (``A0 addr cmd1 cmd2 d1 d2 AF``)."""
    x = 0
    for b in first7:
        x ^= b
    return x


# --------------------------------------------------------------------------------------------
# the decoded frame
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PelcoCommand:
    """One Pelco frame, decoded.  Raw fields plus derived meaning (properties, computed once per
    instance: the parser hands out one instance per distinct Pelco-D frame).

    protocol : 'D' or 'P' (the envelope it came in / goes out in)
    address : logical camera address (D: 0-255, P: 1-256; see module docstring)
    cmd1, cmd2, data1, data2 : the raw bytes (data1 is the *wire* byte: turbo is 0x40 in P)
    """

    protocol: str
    address: int
    cmd1: int
    cmd2: int
    data1: int
    data2: int

    def __post_init__(self) -> None:
        if self.protocol not in FRAME_LEN:
            raise GimbalError(f"Pelco protocol {self.protocol!r} is not allowed; use 'D' or 'P'")
        _check_address(self.address, self.protocol)
        for name in ("cmd1", "cmd2", "data1", "data2"):
            _check_byte(getattr(self, name), name)

    # -- meaning -------------------------------------------------------------------------
    @cached_property
    def is_extended(self) -> bool:
        return bool(self.cmd2 & 0x01)

    @cached_property
    def kind(self) -> str:
        """'stop', 'pan_tilt', 'set_preset', 'clear_preset', 'goto_preset', 'set_pan',
        'set_tilt', 'query_pan', 'query_tilt', 'pan_reply', 'tilt_reply', 'unknown_extended'
        or 'other' (camera functions: zoom, focus, iris, power)."""
        if self.is_extended:
            if self.cmd1 == 0 and self.cmd2 in _EXT_KINDS:
                return _EXT_KINDS[self.cmd2]
            return "unknown_extended"
        if self.cmd1 != 0 or self.cmd2 & 0xE0:
            return "other"
        if self.cmd2 & 0x1E == 0:
            return "stop"
        return "pan_tilt"

    @cached_property
    def pan_dir(self) -> int:
        """+1 = LEFT (pan angle increases), -1 = right, 0 = none (both bits set = 0)."""
        return _dir(self.cmd2, PAN_LEFT, PAN_RIGHT) if not self.is_extended else 0

    @cached_property
    def tilt_dir(self) -> int:
        """+1 = UP (tilt angle increases), -1 = down, 0 = none (both bits set = 0)."""
        return _dir(self.cmd2, TILT_UP, TILT_DOWN) if not self.is_extended else 0

    @cached_property
    def pan_byte(self) -> int:
        """Pan speed byte, with turbo normalised to ``PAN_TURBO`` (0xFF) for both envelopes."""
        if self.protocol == "P" and self.data1 == _P_TURBO_WIRE:
            return PAN_TURBO
        return self.data1

    @property
    def tilt_byte(self) -> int:
        return self.data2

    @property
    def turbo(self) -> bool:
        return self.pan_byte == PAN_TURBO

    @property
    def preset(self) -> int:
        return self.data2

    @property
    def word(self) -> int:
        """The 16-bit big-endian position word in data1:data2 (set/reply frames)."""
        return (self.data1 << 8) | self.data2

    def to_bytes(self) -> bytes:
        return encode(self)


def _dir(cmd2: int, plus_bit: int, minus_bit: int) -> int:
    plus = bool(cmd2 & plus_bit)
    minus = bool(cmd2 & minus_bit)
    return int(plus) - int(minus)


def _check_byte(v: int, name: str) -> None:
    if not isinstance(v, int) or not 0 <= v <= 0xFF:
        raise GimbalError(f"{name}={v!r} is not a byte; allowed 0-255")


def _check_address(address: int, protocol: str) -> None:
    if protocol == "D":
        if not isinstance(address, int) or not 0 <= address <= 255:
            raise GimbalError(f"Pelco-D address {address!r} out of range; allowed 0-255")
    else:
        if not isinstance(address, int) or not 1 <= address <= 256:
            raise GimbalError(
                f"Pelco-P address {address!r} out of range; allowed 1-256 (sent zero-based)"
            )


def _check_protocol(protocol: str) -> None:
    if protocol not in FRAME_LEN:
        raise GimbalError(f"Pelco protocol {protocol!r} is not allowed; use 'D' or 'P'")


# --------------------------------------------------------------------------------------------
# generic encode / decode
# --------------------------------------------------------------------------------------------
def encode(cmd: PelcoCommand) -> bytes:
    """Bytes of a :class:`PelcoCommand` in its envelope (inverse of :func:`decode`)."""
    if cmd.protocol == "D":
        body = bytes((cmd.address, cmd.cmd1, cmd.cmd2, cmd.data1, cmd.data2))
        return bytes((SYNC_D,)) + body + bytes((checksum_d(body),))
    first7 = bytes((STX_P, cmd.address - 1, cmd.cmd1, cmd.cmd2, cmd.data1, cmd.data2, ETX_P))
    return first7 + bytes((checksum_p(first7),))


def decode(frame: bytes | bytearray) -> PelcoCommand:
    """Decode one complete frame (7-byte Pelco-D or 8-byte Pelco-P).

    Raises :class:`PelcoDecodeError` naming what is wrong (length, sync/ETX byte, checksum).
    """
    frame = bytes(frame)
    if len(frame) == 7 and frame[0] == SYNC_D:
        if checksum_d(frame[1:6]) != frame[6]:
            raise PelcoDecodeError(
                f"Pelco-D checksum mismatch in {frame.hex(' ')}: "
                f"expected {checksum_d(frame[1:6]):02x}"
            )
        return PelcoCommand("D", frame[1], frame[2], frame[3], frame[4], frame[5])
    if len(frame) == 8 and frame[0] == STX_P:
        if frame[6] != ETX_P:
            raise PelcoDecodeError(f"Pelco-P frame {frame.hex(' ')} lacks ETX 0xAF at byte 7")
        if checksum_p(frame[:7]) != frame[7]:
            raise PelcoDecodeError(
                f"Pelco-P checksum mismatch in {frame.hex(' ')}: "
                f"expected {checksum_p(frame[:7]):02x}"
            )
        return PelcoCommand("P", frame[1] + 1, frame[2], frame[3], frame[4], frame[5])
    raise PelcoDecodeError(
        f"{frame.hex(' ') or '(empty)'} is not a Pelco frame; allowed: 7 bytes starting FF "
        "(Pelco-D) or 8 bytes starting A0 (Pelco-P)"
    )


def _frame(protocol: str, address: int, cmd1: int, cmd2: int, d1: int, d2: int) -> bytes:
    _check_protocol(protocol)
    return encode(PelcoCommand(protocol, address, cmd1, cmd2, d1, d2))


# --------------------------------------------------------------------------------------------
# the commands
# --------------------------------------------------------------------------------------------
def _speed_byte(b: int, name: str, turbo_ok: bool) -> int:
    if not isinstance(b, int) or not (0 <= b <= MAX_SPEED_BYTE or (turbo_ok and b == PAN_TURBO)):
        allowed = "0x00-0x3F" + (" or 0xFF (turbo)" if turbo_ok else "")
        raise GimbalError(f"{name}={b!r} is not a speed byte; allowed {allowed}")
    return b


def _direction(d: int, name: str) -> int:
    if d not in (-1, 0, 1):
        raise GimbalError(f"{name}={d!r} is not a direction; allowed -1, 0, +1")
    return d


def encode_pan_tilt(
    address: int,
    pan_dir: int,
    pan_byte: int,
    tilt_dir: int,
    tilt_byte: int,
    protocol: str = "D",
) -> bytes:
    """Combined pan/tilt speed move.

    pan_dir : -1 | 0 | +1   (+1 = LEFT: pan angle increases)
    pan_byte : 0x00-0x3F, or 0xFF = turbo (sent as 0x40 in Pelco-P)
    tilt_dir : -1 | 0 | +1   (+1 = UP: tilt angle increases)
    tilt_byte : 0x00-0x3F

    With both directions 0 this is the all-stop frame (speed bytes zeroed, as the standard stop is
    ``00 00 00 00``).
    """
    _direction(pan_dir, "pan_dir")
    _direction(tilt_dir, "tilt_dir")
    _speed_byte(pan_byte, "pan_byte", turbo_ok=True)
    _speed_byte(tilt_byte, "tilt_byte", turbo_ok=False)
    cmd2 = {1: PAN_LEFT, -1: PAN_RIGHT, 0: 0}[pan_dir] | {1: TILT_UP, -1: TILT_DOWN, 0: 0}[tilt_dir]
    if cmd2 == 0:
        return encode_stop(address, protocol)
    d1 = pan_byte if pan_dir else 0
    if protocol == "P" and d1 == PAN_TURBO:
        d1 = _P_TURBO_WIRE
    d2 = tilt_byte if tilt_dir else 0
    return _frame(protocol, address, 0, cmd2, d1, d2)


def encode_stop(address: int, protocol: str = "D") -> bytes:
    """All-stop: cmd1 = cmd2 = d1 = d2 = 0."""
    return _frame(protocol, address, 0, 0, 0, 0)


def _preset(n: int) -> int:
    if not isinstance(n, int) or not 0 <= n <= 255:
        raise GimbalError(f"preset {n!r} out of range; allowed 0-255")
    return n


def encode_set_preset(address: int, preset: int, protocol: str = "D") -> bytes:
    return _frame(protocol, address, 0, OP_SET_PRESET, 0, _preset(preset))


def encode_clear_preset(address: int, preset: int, protocol: str = "D") -> bytes:
    return _frame(protocol, address, 0, OP_CLEAR_PRESET, 0, _preset(preset))


def encode_goto_preset(address: int, preset: int, protocol: str = "D") -> bytes:
    return _frame(protocol, address, 0, OP_GOTO_PRESET, 0, _preset(preset))


def _word_frame(protocol: str, address: int, op: int, word: int) -> bytes:
    if not isinstance(word, int) or not 0 <= word <= 0xFFFF:
        raise GimbalError(f"position word {word!r} out of range; allowed 0-65535")
    return _frame(protocol, address, 0, op, word >> 8, word & 0xFF)


def encode_set_pan_word(address: int, word: int, protocol: str = "D") -> bytes:
    return _word_frame(protocol, address, OP_SET_PAN, word)


def encode_set_tilt_word(address: int, word: int, protocol: str = "D") -> bytes:
    return _word_frame(protocol, address, OP_SET_TILT, word)


def encode_set_pan(address: int, pan_deg: float, protocol: str = "D") -> bytes:
    """Absolute pan (0x4B) to ``pan_deg`` (positive = left, any value; wrapped)."""
    return encode_set_pan_word(address, pan_deg_to_word(pan_deg), protocol)


def encode_set_tilt(
    address: int, tilt_deg: float, protocol: str = "D", tilt_zero: str = "level"
) -> bytes:
    """Absolute tilt (0x4D) to ``tilt_deg`` (positive = up) in the given word convention."""
    return encode_set_tilt_word(address, tilt_deg_to_word(tilt_deg, tilt_zero), protocol)


def encode_query_pan(address: int, protocol: str = "D") -> bytes:
    return _frame(protocol, address, 0, OP_QUERY_PAN, 0, 0)


def encode_query_tilt(address: int, protocol: str = "D") -> bytes:
    return _frame(protocol, address, 0, OP_QUERY_TILT, 0, 0)


def encode_pan_reply(address: int, word: int, protocol: str = "D") -> bytes:
    """Reply to 0x51: ``FF addr 00 59 MSB LSB sum`` (or the Pelco-P envelope)."""
    return _word_frame(protocol, address, OP_PAN_REPLY, word)


def encode_tilt_reply(address: int, word: int, protocol: str = "D") -> bytes:
    """Reply to 0x53: ``FF addr 00 5B MSB LSB sum`` (or the Pelco-P envelope)."""
    return _word_frame(protocol, address, OP_TILT_REPLY, word)


# --------------------------------------------------------------------------------------------
# angles <-> words
# --------------------------------------------------------------------------------------------
TILT_ZEROS = ("level", "zenith")


def wrap_pan_deg(pan_deg):
    """Wrap to (-180, 180] (works on floats and numpy arrays)."""
    if type(pan_deg) is float and math.isfinite(pan_deg):
        # a plain float without numpy: the same operations, so the same bits (per-frame hot path)
        # (np.ceil gives -0.0 on (-1, 0]; math.ceil an int, so the zero's sign is put back)
        y = (pan_deg - 180.0) / 360.0
        c = math.ceil(y)
        return pan_deg - 360.0 * (float(c) if c else math.copysign(0.0, y))
    import numpy as np

    x = np.asarray(pan_deg, dtype=float)
    w = x - 360.0 * np.ceil((x - 180.0) / 360.0)
    return float(w) if w.ndim == 0 else w


def pan_deg_to_word(pan_deg: float) -> int:
    return int(round(float(pan_deg) * 100.0)) % WORD_MODULUS


def word_is_angle(word: int) -> bool:
    """True if ``word`` is a possible position (0-35999)."""
    return 0 <= word < WORD_MODULUS


def word_to_pan_deg(word: int) -> float:
    if not word_is_angle(word):
        raise GimbalError(f"position word {word} is not an angle; allowed 0-35999")
    return wrap_pan_deg(word / 100.0)


def tilt_deg_to_word(tilt_deg: float, tilt_zero: str = "level") -> int:
    if tilt_zero not in TILT_ZEROS:
        raise GimbalError(f"tilt_zero={tilt_zero!r} is not allowed; use 'level' or 'zenith'")
    down_deg = -float(tilt_deg) if tilt_zero == "level" else 90.0 - float(tilt_deg)
    return int(round(down_deg * 100.0)) % WORD_MODULUS


def word_to_tilt_deg(word: int, tilt_zero: str = "level") -> float:
    """Inverse of :func:`tilt_deg_to_word`; result in (-180, 180]."""
    if tilt_zero not in TILT_ZEROS:
        raise GimbalError(f"tilt_zero={tilt_zero!r} is not allowed; use 'level' or 'zenith'")
    if not word_is_angle(word):
        raise GimbalError(f"position word {word} is not an angle; allowed 0-35999")
    down_deg = word / 100.0
    tilt = -down_deg if tilt_zero == "level" else 90.0 - down_deg
    return wrap_pan_deg(tilt)
