"""Crafted chunks (issue 32): records whose chunk CRC holds but whose bytes are not what our writer
makes.  A channel record too short for its strings or with a string length past its end, a JSON
record that is not an object, one nested past Python's recursion limit: each was a traceback
(struct.error in ``mcap_walk.string``, AttributeError in ``metrics.flatten``, RecursionError in
``json``).  Now a record that does not hold together makes its chunk damage (skipped, named in a
WARNING) and a message of the wrong shape is the one-line error naming the file, the channel and
the log time, as the typed records already are."""

import struct
import sys
from pathlib import Path

import pytest

from foveatrack.cli import main

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "scripts"))
import make_fuzz_corpus as corpus  # noqa: E402 - its MCAP surgery helpers

EMPTY = ROOT / "tests" / "corpus" / "no-frames.mcap"


def _crafted(tmp_path, records: bytes) -> Path:
    """The empty recording up to its end-of-data record and one lz4 chunk of ``records`` (CRC right)."""
    from foveatrack.recording import mcap_walk as mw

    empty = EMPTY.read_bytes()
    _chunks, e_end = corpus.mcap_layout(empty)
    p = tmp_path / "crafted.mcap"
    p.write_bytes(empty[:e_end] + corpus.lz4_chunk(records, 10**9))
    assert mw.OP_CHANNEL
    return p


def _run(capsys, argv):
    rc = main(argv)
    out, err = capsys.readouterr()
    return rc, out, err


def _commands(p, tmp_path):
    return [["replay", str(p), "--json"],
            ["export", str(p), "--csv", str(tmp_path / "p.csv"), "--trajectory", str(tmp_path / "t.csv"),
             "--lvx", str(tmp_path / "p.lvx")]]


def _channel(body: bytes) -> bytes:
    from foveatrack.recording import mcap_walk as mw

    return corpus.record(mw.OP_CHANNEL, body)


@pytest.mark.parametrize("body,why", [
    (b"\x01\x00", "a channel record of 2 bytes"),
    (struct.pack("<HH", 5, 0), "a string at byte 4 of a record of 4 bytes"),
    (struct.pack("<HH", 5, 0) + struct.pack("<I", 2**32 - 1) + b"ab", "a string of 4294967295 bytes"),
])
def test_a_channel_record_that_does_not_hold_together_is_damage(tmp_path, capsys, body, why):
    p = _crafted(tmp_path, _channel(body))
    for argv in _commands(p, tmp_path):
        rc, out, err = _run(capsys, argv)
        assert rc == 0, (argv[0], err)
        warnings = [ln for ln in (out + err).splitlines() if "WARNING" in ln]
        if argv[0] == "export":
            assert len(warnings) == 1 and str(p) in warnings[0] and why in warnings[0], err
        else:
            assert why in out, out        # replay --json names it in recording_damage


@pytest.mark.parametrize("channel,payload,why", [
    ("/head", b"[1, 2]", "a JSON list, not an object"),
    ("/daemon", b"[" * 100_000 + b"]" * 100_000, "JSON nested too deep"),
])
def test_a_json_record_of_the_wrong_shape_is_a_one_line_error(tmp_path, capsys, channel, payload, why):
    p = _crafted(tmp_path, corpus.channel_record(7, channel, "json") + corpus.message_record(7, 10**9, payload))
    for argv in _commands(p, tmp_path):
        rc, out, err = _run(capsys, argv)
        if argv[0] == "export" and channel == "/daemon":
            assert rc == 0, err        # export reads no daemon events: nothing of it is decoded
            continue
        lines = [ln for ln in err.splitlines() if ln.startswith("foveatrack: error:")]
        assert rc == 2 and len(lines) == 1 and "Traceback" not in err, (argv[0], err)
        assert str(p) in lines[0] and f"a {channel[1:]} message at log time 1000000000 ns is damaged" in lines[0]
        assert why in lines[0]
