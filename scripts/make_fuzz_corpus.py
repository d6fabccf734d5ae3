"""Write the regression corpus of damaged and hostile files (issue 32) into ``tests/corpus/``.

Each reproducer the issue lists, and each the fuzz harness (``scripts/fuzz_files.py --keep DIR``)
found, is remade here by hand on small intact files (a 0.5 s simulator recording with one point in
50 kept, its ``.lvx`` export, the harness's scene and daemon config), so the corpus stays well under
1 MB.  ``tests/corpus/corpus.json`` names each file, the command it goes through (``{file}`` is its
path, ``{out}`` an output directory) and what must come out: ``error`` (rc 2, one line), ``warning``
(rc 0 and a WARNING naming the loss) or ``ok`` (rc 0: a valid result, e.g. an empty recording).
``tests/test_fuzz_corpus.py`` runs them all through the CLI.

Usage: python scripts/make_fuzz_corpus.py   (same bits every time: the simulator is deterministic)
"""

from __future__ import annotations

import json
import re
import struct
import sys
import tempfile
import zlib
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
OUT = ROOT / "tests" / "corpus"
THIN = 50                      # keep one point in THIN of the simulator's frames: small files


def small_recording(path: Path, frames: bool = True) -> None:
    """The daemon test scene for 0.5 s, one point in THIN recorded (``frames=False``: none at all,
    as the daemon leaves a run in which the lidar never sent data)."""
    from foveatrack.frames import Frame
    from foveatrack.recording import RecordingWriter
    from sim.loop import ClosedLoop
    from sim.recorder import SimRecorder, recording_meta
    from sim.scene import load_scene, with_run_overrides

    scene = with_run_overrides(load_scene(ROOT / "tests" / "daemon" / "scene_track.toml"), 0.5, None)
    loop = ClosedLoop(scene)
    with RecordingWriter(path, recording_meta(scene, loop), created_utc="fixed", overwrite=True) as w:
        rec = SimRecorder(w)

        def thin(frame, out, loop_):
            k = slice(None, None, THIN)
            rec(Frame(frame.t_start_s, frame.t_end_s, frame.xyz[k], frame.t_ns[k],
                      None if frame.reflectivity is None else frame.reflectivity[k]), out, loop_)

        if frames:
            loop.frame_hook = thin
            loop.run()


# ------------------------------------------------------------------------------------ MCAP surgery
def mcap_layout(data: bytes):
    """(offset, length) of every chunk record in the data section, and where the end-of-data record starts."""
    from foveatrack.recording import mcap_walk as mw

    f = len(data) - 8 - mw.FOOTER_SIZE
    summary_start = struct.unpack_from("<Q", data, f + 9)[0]
    data_end = (summary_start or f) - mw.DATA_END_SIZE
    pos, chunks = 8, []
    while pos < data_end:
        op, length = mw.REC.unpack_from(data, pos)
        if op == mw.OP_CHUNK:
            chunks.append((pos, length))
        pos += mw.REC.size + length
    return chunks, data_end


def chunk_records(data: bytes, pos: int):
    from foveatrack.recording import mcap_walk as mw

    return mw.chunk_records(data, pos, mw.REC.unpack_from(data, pos)[1])


def record(op: int, body: bytes) -> bytes:
    from foveatrack.recording import mcap_walk as mw

    return mw.REC.pack(op, len(body)) + body


def string(s: str) -> bytes:
    return struct.pack("<I", len(s)) + s.encode()


def channel_record(cid: int, topic: str, encoding: str) -> bytes:
    from foveatrack.recording import mcap_walk as mw

    return record(mw.OP_CHANNEL, struct.pack("<HH", cid, 0) + string(topic) + string(encoding) + struct.pack("<I", 0))


def message_record(cid: int, t_ns: int, payload: bytes) -> bytes:
    from foveatrack.recording import mcap_walk as mw

    return record(mw.OP_MESSAGE, mw.MSG_HEAD.pack(cid, 0, t_ns, t_ns) + payload)


def lz4_chunk(records: bytes, t_ns: int = 1_000_000_000, usize: int | None = None, crc: int | None = None) -> bytes:
    import lz4.frame

    from foveatrack.recording import mcap_walk as mw

    comp = lz4.frame.compress(records)
    body = (mw.CHUNK_HEAD.pack(t_ns, t_ns, len(records) if usize is None else usize,
                               zlib.crc32(records) if crc is None else crc, 3)
            + b"lz4" + mw.U64.pack(len(comp)) + comp)
    return record(mw.OP_CHUNK, body)


def first_payload(data: bytes, chunks, topic: str) -> tuple[bytes, str]:
    """The first message of ``topic`` (without '/') and its channel's encoding."""
    from foveatrack.recording import mcap_walk as mw

    names = {}
    for pos, _ in chunks:
        for op, content in chunk_records(data, pos):
            if op == mw.OP_CHANNEL:
                cid, name, enc = content
                names[cid] = (name, enc)
            elif op == mw.OP_MESSAGE:
                cid = mw.MSG_HEAD.unpack_from(content, 0)[0]
                if names.get(cid, ("",))[0] == topic:
                    return bytes(content[mw.MSG_HEAD.size:]), names[cid][1]
    raise LookupError(topic)


def thin_lvx(lvx: bytes, keep_every: int = 20) -> tuple[bytes, list[int]]:
    """The export with one package in ``keep_every`` of each frame kept (a 0.5 s Mid-40 export is
    650 kB of mostly no-return slots), and the byte offset of each frame."""
    from foveatrack.livox import protocol as P
    from foveatrack.livox.lvx import FRAME_HEADER, PACKAGE_HEADER_LEN, LvxReader, write_lvx

    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "x.lvx"
        p.write_bytes(lvx)
        with LvxReader(p) as r:
            devices, frame_ms, pos = r.devices, r.frame_duration_ms, r.data_offset
        frames = []
        while pos < len(lvx):
            _cur, nxt, _i = FRAME_HEADER.unpack_from(lvx, pos)
            body, i, pk = lvx[pos + FRAME_HEADER.size:nxt], 0, []
            while i < len(body):
                dtype = body[i + 10]
                n = PACKAGE_HEADER_LEN + P.POINTS_PER_PACKET[dtype] * P.POINT_DTYPES[dtype].itemsize
                pk.append((body[i], body[i + 1:i + n]))
                i += n
            frames.append(pk[::keep_every])
            pos = nxt
        q = Path(tmp) / "thin.lvx"
        write_lvx(q, frames, devices, frame_ms)
        with LvxReader(q) as r:
            pos = r.data_offset
        out = q.read_bytes()
    offsets = []
    while pos < len(out):
        offsets.append(pos)
        pos = FRAME_HEADER.unpack_from(out, pos)[1]
    return out, offsets


# ------------------------------------------------------------------------------------ the corpus
def build(out: Path) -> list[dict]:
    from foveatrack.cli import main as cli
    from foveatrack.recording import mcap_walk as mw

    out.mkdir(parents=True, exist_ok=True)
    for f in out.glob("*"):
        if f.suffix in (".mcap", ".lvx", ".toml", ".json"):
            f.unlink()
    entries: list[dict] = []

    def add(name: str, data, argv: list[str], expect: str, what: str, match: str | None = None):
        """One entry: ``data`` written as ``name`` (None: a file added before, with another command)."""
        p = out / name
        if data is not None:
            (p.write_text if isinstance(data, str) else p.write_bytes)(data)
        entries.append({"file": name, "argv": argv, "expect": expect, "match": match, "what": what})

    replay = ["replay", "{file}", "--json"]
    export_csv = ["export", "{file}", "--csv", "{out}/p.csv"]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        base_p = tmp / "small.mcap"
        small_recording(base_p)
        base = base_p.read_bytes()
        empty_p = tmp / "empty.mcap"
        small_recording(empty_p, frames=False)
        empty = empty_p.read_bytes()
        lvx_p = tmp / "small.lvx"
        assert cli(["export", str(base_p), "--lvx", str(lvx_p)]) == 0
        lvx = lvx_p.read_bytes()
    chunks, data_end = mcap_layout(base)
    assert len(chunks) >= 4, len(chunks)
    _, e_end = mcap_layout(empty)

    add("intact.mcap", base, replay, "ok", "the intact small recording")
    add("intact.mcap", None, ["export", "{file}", "--csv", "{out}/p.csv", "--lvx", "{out}/p.lvx",
                                     "--trajectory", "{out}/t.csv"], "ok", "the intact small recording, exported")
    add("no-frames.mcap", empty, replay, "ok",
        "a recording with no frames crashed replay (TypeError in replay/metrics.py)")
    add("no-frames.mcap", None, ["export", "{file}", "--csv", "{out}/p.csv", "--lvx",
                                                       "{out}/p.lvx"], "ok", "a recording with no frames, exported")

    # intact chunks out of order: a later chunk (and its message index) copied over an earlier one
    (a, la), (b, lb) = chunks[1], chunks[-2]
    d = bytearray(base)
    seg = base[b:chunks[-1][0]]
    d[a:a + len(seg)] = seg
    add("out-of-order.mcap", bytes(d), replay, "warning",
        "intact chunks out of order crashed replay ('commands must come in time order')", "out of time order")

    # one bit of a chunk's CRC: replay said "1 frame ... lost", export said nothing
    d = bytearray(base)
    d[chunks[2][0] + 9 + 24] ^= 0x01
    add("crc-bit.mcap", bytes(d), export_csv, "warning", "export never reported damage (one flipped bit)",
        "1 frame")
    add("crc-bit.mcap", None, ["export", "{file}", "--lvx", "{out}/p.lvx"], "warning",
        "export --lvx never reported damage (one flipped bit)", "1 frame")

    # a chunk CRC of 0 meant "unchecked"
    d = bytearray(base)
    d[chunks[2][0] + 9 + 24:chunks[2][0] + 9 + 28] = bytes(4)
    add("crc-zero.mcap", bytes(d), replay, "warning", "a chunk CRC of 0 meant 'unchecked'", "without a CRC")

    # the metadata record had no checksum: format version 3 -> 2 decoded every point differently
    i = base.index(b"format_version")
    j = base.index(b"3", i + len("format_version") + 4)
    d = bytearray(base)
    d[j] = ord("2")
    add("meta-version.mcap", bytes(d), replay, "error", "one bit of the metadata turned format version 3 into 2",
        "metadata record is damaged")

    # an lz4 chunk with no output cap (2.5 MB -> 864 MB): one that claims 64x its size and more
    import lz4.frame

    bomb = lz4.frame.compress(b"\0" * (8 << 20))
    body = mw.CHUNK_HEAD.pack(2_000_000_000, 2_000_000_000, 8 << 20, 0, 3) + b"lz4" + mw.U64.pack(len(bomb)) + bomb
    add("lz4-bomb.mcap", empty[:e_end] + record(mw.OP_CHUNK, body), export_csv, "warning",
        "lz4 chunks had no output cap (2.5 MB -> 864 MB)", "implausible uncompressed size")

    # millions of frames claimed by a small file: one empty frame repeated in lz4 chunks
    payload, enc = first_payload(base, chunks, "points")
    from foveatrack.recording import RecordingWriter

    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "one.mcap"
        with RecordingWriter(p, {}) as w:
            w.write_points(1_000_000_000, 0, np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0, np.uint8))
        one = p.read_bytes()
    oc, _ = mcap_layout(one)
    empty_frame, enc = first_payload(one, oc, "points")
    many = lz4_chunk(channel_record(900, "/points", enc) + message_record(900, 10**9, empty_frame) * 8000)
    add("many-frames.mcap", empty[:e_end] + many * 12, replay, "warning",
        "a small file claiming ~100 000 frames (a 4 MB .lvx became 1.79 M tracker frames, 1.6 GB)",
        "cap on frames per file")
    add("many-frames.mcap", None, export_csv, "warning",
        "a small file claiming ~100 000 frames, exported", "cap on frames per file")

    # type confusion in crafted chunks: records of the right channel with values of the wrong type
    last_t = 10**9
    confused = [
        ("detections", {"t_ns": last_t, "frame_id": 4, "detected": True, "xyz_m": "abc", "n_points": []}),
        ("head", {"t_ns": last_t, "frame_id": 4, "pan_deg": {}, "tilt_deg": None}),
        ("commands", {"t_ns": last_t, "raw_hex": "zz", "frame_id": 4, "source": "tracker", "send_t_s": "x"}),
        ("truth", {"t_ns": last_t, "frame_id": 4, "true_target_world_m": [1, 2], "points_on_target": "x"}),
        ("metrics", {"t_ns": last_t, "name": [], "value": {}}),
        ("daemon", {"t_ns": last_t, "event": "tracker_rebased", "t0_s": "x", "pan_deg": None}),
        ("points", None),
    ]
    for k, (topic, rec_) in enumerate(confused):
        cid = 910 + k
        if topic == "points":
            recs = channel_record(cid, "/points", enc) + message_record(cid, last_t, b"\x0a\x05garbage" + payload[:40])
        else:
            recs = channel_record(cid, "/" + topic, "json") + message_record(cid, last_t, json.dumps(rec_).encode())
        points_again = channel_record(909, "/points", enc) + message_record(909, last_t, payload)
        data = empty[:e_end] + lz4_chunk(points_again + recs, last_t)
        add(f"type-{topic}.mcap", data, replay, "error", f"type confusion in a crafted {topic} record (a traceback "
            f"in records.py from_json, metrics.py or replay/driver.py)", "is damaged")
        # export copies records as they are (the trajectory's columns), and decodes only the points
        add(f"type-{topic}.mcap", None, ["export", "{file}", "--csv", "{out}/p.csv", "--trajectory",
                                         "{out}/t.csv", "--lvx", "{out}/p.lvx"], "error" if topic == "points" else "ok",
            f"type confusion in a crafted {topic} record, exported", "is damaged" if topic == "points" else None)

    # ---------------------------------------------------------------- .lvx
    from foveatrack.livox.lvx import FRAME_HEADER, LvxReader, write_lvx

    lvx, frame_offsets = thin_lvx(lvx)
    mid = frame_offsets[len(frame_offsets) // 2]
    ts_at = mid + FRAME_HEADER.size + 11

    def lvx_with_ts(value: int) -> bytes:
        d = bytearray(lvx)
        d[ts_at:ts_at + 8] = value.to_bytes(8, "little")
        return bytes(d)

    lvx_replay = ["replay", "{file}", "--json", "--tracker-config", "{corpus}/daemon.toml"]
    add("intact.lvx", lvx, lvx_replay, "ok", "the intact small .lvx")
    add("ts-7fff.lvx", lvx_with_ts(0x7FFF_FFFF_FFFF_FFFF), lvx_replay, "error",
        "an LVX package stamped 0x7fff... crashed replay (u64 -> int64 wrap in protocol.decode_packets_array)",
        "field timestamp")
    t_mid = int.from_bytes(lvx[ts_at:ts_at + 8], "little")
    add("late-18min.lvx", lvx_with_ts(t_mid + 18 * 60 * 10**9), lvx_replay, "warning",
        "one package stamped 18 minutes late silently discarded ~70 % of the file", "dropped")
    d = bytearray(lvx)
    for off in frame_offsets[len(frame_offsets) // 2:]:     # every later frame's first package: PTP time
        at = off + FRAME_HEADER.size + 11
        d[at:at + 8] = (int.from_bytes(d[at:at + 8], "little") + 1_700_000_000 * 10**9).to_bytes(8, "little")
    add("clock-jump.lvx", bytes(d), lvx_replay, "warning", "the first package of every later frame stamped as after "
        "a sensor clock jump (power-on time to PTP time)", "points dropped")

    # ---------------------------------------------------------------- scenes and configs
    scene = (ROOT / "tests" / "daemon" / "scene_track.toml").read_text().replace("duration_s = 3.0", "duration_s = 1.0")
    simulate = ["simulate", "{file}", "--duration", "1", "--no-progress"]
    block = scene[scene.index("[[target]]"):scene.index("[[background]]")]
    add("targets-300.toml", scene + ("\n" + block) * 300, simulate, "error",
        "a scene of 100 000 targets ran on with no cap", "targets")
    add("scene-preset-list.toml", re.sub(r'(?m)^preset\s*=.*$', "preset = []", scene, count=1), simulate, "error",
        "a scene preset that is not a name")
    add("scene-nested.toml", scene + "x = " + "[" * 1000 + "]" * 1000 + "\n", simulate, "error",
        "a TOML nested 1000 deep (RecursionError)")
    add("scene-nul-speed-table.toml", re.sub(r'(?m)^speed_table\s*=.*$', lambda m: 'speed_table = "\\u0000"', scene,
                                             count=1), simulate, "error",
        "a NUL in [gimbal] speed_table (the full scene campaign's 4 tracebacks: ValueError: embedded null byte)",
        "NUL")

    cfg = (ROOT / "examples" / "daemon-virtual.toml").read_text()
    cfg = re.sub(r'(?m)^speed_table\s*=.*$', 'speed_table = "nominal"', cfg)
    cfg = re.sub(r'(?m)^port\s*=.*$', 'port = "loop://"', cfg)
    (out / "daemon.toml").write_text(cfg)
    check = ["daemon", "--config", "{file}", "--check"]
    add("config-intact.toml", cfg, check, "ok", "the intact daemon config")
    add("config-nested.toml", cfg + "x = " + "{a = " * 600 + "1" + "}" * 600 + "\n", check, "error",
        "a TOML nested 600 deep (RecursionError)")
    add("config-nested-arrays.toml", cfg + "y = " + "[" * 1000 + "]" * 1000 + "\n", check, "error",
        "a TOML array nested 1000 deep (RecursionError)")
    add("config-preset-list.toml", cfg.replace("[lidar]\n", "[lidar]\npreset = []\n", 1), check, "error",
        "[lidar] preset = []", "preset")
    no_tracker = cfg[:cfg.index("[tracker]")] + cfg[cfg.index("[recording]"):]
    add("config-tracker-1.toml", "tracker = 1\n" + no_tracker, check, "error", "tracker = 1", "tracker")
    add("config-nul-port.toml", re.sub(r'(?m)^port\s*=.*$', lambda m: 'port = "\\u0000"', cfg, count=1),
        check, "error", "a NUL in [head] port")
    add("config-nul-recording-path.toml",
        re.sub(r'(?m)^path\s*=.*$', lambda m: 'path = "\\u0000"', cfg, count=1), check, "error",
        "a NUL in [recording] path (found by the full campaign: ValueError: embedded null byte)", "NUL")
    add("config-nul-speed-table.toml",
        re.sub(r'(?m)^speed_table\s*=.*$', lambda m: 'speed_table = "t\\u0000.json"', cfg, count=1), check, "error",
        "a NUL in [head] speed_table", "NUL")
    add("config-devzero.toml", re.sub(r'(?m)^speed_table\s*=.*$', 'speed_table = "/dev/zero"', cfg), check, "error",
        "speed_table = '/dev/zero' (3.5 GB, then MemoryError)")

    # command-line values of the same family, on the intact recording
    entries.append({"file": "intact.mcap", "argv": ["replay", "{file}", "--live", "0", "--wait-s", "inf"],
                    "expect": "error", "match": "--wait-s", "what": "--wait-s inf (OverflowError)"})
    entries.append({"file": "intact.mcap", "argv": ["replay", "{file}", "--live", "0", "--speed", "1e-300"],
                    "expect": "error", "match": "--speed", "what": "--speed 1e-300 (OverflowError)"})
    (out / "corpus.json").write_text(json.dumps(entries, indent=1) + "\n")
    return entries


if __name__ == "__main__":
    es = build(OUT)
    total = sum(f.stat().st_size for f in OUT.iterdir() if f.is_file())
    print(f"{len(es)} entries, {len(list(OUT.iterdir()))} files, {total} bytes in {OUT}")
