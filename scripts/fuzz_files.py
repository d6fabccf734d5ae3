"""Mutation fuzzing of the file paths (issue 32): recordings, .lvx files, scenes and daemon configs
through the real CLI, each trial in a forked child under an address-space limit and a timeout.

Every trial ends in one of: ``clean error`` (rc 2, one line), ``warning+partial`` (rc 0 and a
WARNING / note on the output), ``same`` (rc 0, the output the intact file gives), ``silent difference``
(rc 0, no warning, another output than the intact file's, the files it wrote included; for scenes and configs a mutated value may
rightly change the output: "silent" is meaningful for recordings and .lvx files only), ``traceback`` (any other exception,
or a child that died), ``hang`` (over the timeout), ``memory error`` (MemoryError under the address-space limit).

Two ways to run a trial (``--mode``): ``inprocess`` (default, fast) calls the CLI's ``main`` in a child
forked from this process, which has imported foveatrack and compiled its kernels once; ``subprocess``
starts ``python -m foveatrack`` afresh for each trial (the real entry point, interpreter start-up and
imports included: slower, for checking that the in-process trials tell the truth).  The inputs of
tracebacks, hangs, memory errors and silent differences are kept in ``--keep DIR`` (seed and trial in
the name) for the regression corpus (``tests/corpus``).

Usage::

    python scripts/fuzz_files.py --minutes 5 --seed 1 [--campaign mcap-replay ...] [--keep DIR]
    python scripts/fuzz_files.py --trials 2371 --seed 7 --campaign mcap-export --mode subprocess

Campaigns: ``mcap-replay`` (replay --json), ``mcap-export`` (export --csv), ``lvx-replay`` (replay
--json of a .lvx), ``scene`` (simulate --duration 1), ``config`` (daemon --check).  Same seed, same
mutations.  Prints the table of the issue, one row per campaign.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import math
import os
import resource
import shutil
import signal
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

OUTCOMES = ("clean error", "warning+partial", "same", "silent difference", "traceback", "hang", "memory error")
AS_LIMIT_BYTES = 4 << 30
TIMEOUT_S = 30.0           # of CPU time: a trial that computes longer is a hang
WALL_S = 300.0             # of wall time: a trial that waits longer (a sleep, a blocked read) is a hang


# ----------------------------------------------------------------------------------------- mutations
def mutate_bytes(data: bytes, rng: np.random.Generator) -> bytes:
    """One of: flip a bit, set a byte, copy 64 KiB (or less) to an earlier offset, cut the tail,
    insert random bytes, overwrite a run with a wild u64 (0x7fff... or a clock jump)."""
    d = bytearray(data)
    n = len(d)
    kind = int(rng.integers(6))
    i = int(rng.integers(n))
    if kind == 0:
        d[i] ^= 1 << int(rng.integers(8))
    elif kind == 1:
        d[i] = int(rng.integers(256))
    elif kind == 2:
        src = int(rng.integers(n // 2, n))
        dst = int(rng.integers(0, max(src, 1)))
        L = min(65536, n - src)
        d[dst:dst + L] = d[src:src + L]
    elif kind == 3:
        del d[i:]
    elif kind == 4:
        d[i:i] = rng.integers(0, 256, int(rng.integers(1, 64)), dtype=np.uint8).tobytes()
    else:
        v = (0x7FFF_FFFF_FFFF_FFFF, 0xFFFF_FFFF_FFFF_FFFF, 1_700_000_000_000_000_000)[int(rng.integers(3))]
        d[i:i + 8] = v.to_bytes(8, "little")[: max(0, min(8, n - i))]
    return bytes(d)


TOML_VALUES = ["[]", "1", "-1", "1e308", "nan", "inf", '"\\u0000"', '"/dev/zero"', "{}", "true", '""',
               "[" * 1000 + "]" * 1000, "100000", "0"]


def mutate_toml(text: str, rng: np.random.Generator) -> str:
    """One of: a value replaced by a hostile one, a line dropped, a line doubled, a table nested deep,
    many copies of an array of tables."""
    lines = text.splitlines()
    kind = int(rng.integers(5))
    i = int(rng.integers(len(lines)))
    if kind == 0 and "=" in lines[i]:
        k = lines[i].split("=", 1)[0]
        lines[i] = f"{k}= {TOML_VALUES[int(rng.integers(len(TOML_VALUES)))]}"
    elif kind == 1:
        del lines[i]
    elif kind == 2:
        lines.insert(i, lines[i])
    elif kind == 3:
        lines.append("x = " + "{a = " * 600 + "1" + "}" * 600)
    else:
        blocks = [ln for ln in lines if ln.startswith("[[")]
        if blocks:
            start = lines.index(blocks[0])
            end = next((j for j in range(start + 1, len(lines)) if lines[j].startswith("[")), len(lines))
            lines += lines[start:end] * int(rng.integers(2, 2000))
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------------------- trials
def run_cli(args: list[str]) -> tuple[int, str]:
    """``foveatrack ARGS`` in this process: (rc, stdout + stderr); an exception escapes."""
    from foveatrack.cli import main

    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
        rc = main(args)
    return int(rc or 0), out.getvalue()


def trial(args: list[str], timeout_s: float, mode: str = "inprocess",
          wall_s: float | None = None) -> tuple[str, int | None, str]:
    """Run one CLI call, limits applying to it alone: (kind, rc, output); kind is "ok", "traceback",
    "memory error" or "hang".  ``inprocess``: ``main`` in a forked child; ``subprocess``: ``python -m
    foveatrack`` in a fresh interpreter.  A hang is ``timeout_s`` of CPU time (RLIMIT_CPU) or
    ``wall_s`` (default ``timeout_s``) of wall time: on a machine shared with busier processes a
    niced trial of 1 s of CPU can wait 30 s for it, and was counted a hang by a wall limit alone."""
    wall_s = timeout_s if wall_s is None else wall_s
    if mode == "subprocess":
        return _trial_subprocess(args, timeout_s, wall_s)
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:     # the child
        os.close(r)
        code = 0
        try:
            _limit_child(timeout_s)
            rc, text = run_cli(args)
            payload = f"rc {rc}\n{text}"
        except SystemExit as exc:
            payload = f"rc {exc.code if isinstance(exc.code, int) else 2}\n"
        except MemoryError as exc:
            import traceback

            payload = "memory error\n" + "".join(traceback.format_exception(exc))[-4000:]
        except BaseException as exc:   # noqa: BLE001 - what the fuzzer looks for
            import traceback

            payload = "traceback\n" + "".join(traceback.format_exception(exc))[-4000:]
        try:
            with os.fdopen(w, "w") as fh:
                fh.write(payload)
        finally:
            os._exit(code)
    os.close(w)
    t_end = time.monotonic() + wall_s
    chunks = []
    os.set_blocking(r, False)
    while True:
        try:
            b = os.read(r, 65536)
            if b:
                chunks.append(b)
        except BlockingIOError:
            pass
        if time.monotonic() > t_end:
            os.kill(pid, signal.SIGKILL)
            _, _, usage = os.wait4(pid, 0)
            LAST_CPU_S[0] = usage.ru_utime + usage.ru_stime
            os.close(r)
            return "hang", None, ""
        done, status, usage = os.wait4(pid, os.WNOHANG)
        if done:
            LAST_CPU_S[0] = usage.ru_utime + usage.ru_stime
            os.set_blocking(r, True)
            while b := os.read(r, 65536):
                chunks.append(b)
            break
        time.sleep(0.005)
    os.close(r)
    text = b"".join(chunks).decode(errors="replace")
    for kind in ("traceback", "memory error"):
        if text.startswith(kind + "\n"):
            return kind, None, text
    if not text and os.WIFSIGNALED(status) and os.WTERMSIG(status) in (signal.SIGXCPU, signal.SIGKILL):
        return "hang", None, f"over {timeout_s:g} s of CPU time"
    if not text:
        return "traceback", None, f"child died (wait status {status}: a signal, or memory)"
    first, _, rest = text.partition("\n")
    return "ok", int(first.split()[1]), rest


LAST_CPU_S = [0.0]     # the CPU seconds of the last trial's process (user + system), for --log


def _limit_child(cpu_s: float) -> None:
    resource.setrlimit(resource.RLIMIT_AS, (AS_LIMIT_BYTES, AS_LIMIT_BYTES))
    # SIGXCPU at the soft limit, SIGKILL at the hard one (a handler that ignores SIGXCPU)
    resource.setrlimit(resource.RLIMIT_CPU, (math.ceil(cpu_s), math.ceil(cpu_s) + 5))


def _trial_subprocess(args: list[str], timeout_s: float, wall_s: float) -> tuple[str, int | None, str]:
    import subprocess

    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    try:
        p = subprocess.run([sys.executable, "-m", "foveatrack", *args], capture_output=True, text=True,
                           timeout=wall_s, preexec_fn=lambda: _limit_child(timeout_s), env=env,
                           stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        return "hang", None, ""
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    LAST_CPU_S[0] = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    if p.returncode in (-signal.SIGXCPU, -signal.SIGKILL):
        return "hang", None, f"over {timeout_s:g} s of CPU time"
    text = p.stdout + p.stderr
    if "MemoryError" in p.stderr and "Traceback" in p.stderr:
        return "memory error", None, text
    if "Traceback (most recent call last)" in p.stderr or p.returncode not in (0, 2):
        return "traceback", None, text
    return "ok", p.returncode, text


def classify(kind: str, rc: int | None, out: str, baseline: str, normalise) -> str:
    if kind != "ok":
        return kind
    if rc == 2:
        return "clean error"
    if rc != 0:
        return "traceback"
    if "WARNING" in out or "note:" in out or '"recording_damage": [\n' in out or '"recording_problem"' in out:
        return "warning+partial"
    return "same" if normalise(out) == normalise(baseline) else "silent difference"


# ----------------------------------------------------------------------------------------- inputs
def make_inputs(work: Path) -> dict:
    """The intact files each campaign mutates: a simulator recording of the daemon test scene, its
    .lvx export, the scene and an example daemon config."""
    from foveatrack.recording import RecordingWriter
    from sim.loop import ClosedLoop
    from sim.recorder import SimRecorder, recording_meta
    from sim.scene import load_scene

    scene_path = ROOT / "tests" / "daemon" / "scene_track.toml"
    scene = load_scene(scene_path)
    scene_text = scene_path.read_text().replace("duration_s = 3.0", "duration_s = 1.0")
    loop = ClosedLoop(load_scene(scene_path))
    rec = work / "intact.mcap"
    with RecordingWriter(rec, recording_meta(scene, loop), created_utc="fixed") as w:
        loop.frame_hook = SimRecorder(w)
        loop.run()
    lvx = work / "intact.lvx"
    run_cli(["export", str(rec), "--lvx", str(lvx)])
    configs = sorted((ROOT / "examples").glob("*.toml"))
    daemon_cfg = next((p for p in configs if "[lidar]" in p.read_text() and "[head]" in p.read_text()), None)
    cfg_text = None
    if daemon_cfg:   # a speed table named relative to the example would not be found beside the copy
        import re

        cfg_text = re.sub(r'(?m)^speed_table\s*=.*$', 'speed_table = "nominal"', daemon_cfg.read_text())
        cfg_text = re.sub(r'(?m)^port\s*=.*$', 'port = "loop://"', cfg_text)   # --check opens the head's port
    return {"mcap": rec.read_bytes(), "lvx": lvx.read_bytes(), "scene": scene_text, "config": cfg_text}


def _drop_paths(text: str) -> str:
    """The output without what changes from run to run: paths, wall times, progress bars."""
    return "\n".join(ln for ln in text.splitlines()
                     if "->" not in ln and "/" not in ln and " wall" not in ln and "frame/s" not in ln)


def output_digests(out_dir: Path) -> str:
    """A line per file the command wrote (``p.*``) with its SHA-256: an export that prints the intact
    file's point count but writes other points is a silent difference too."""
    import hashlib

    return "".join(f"\noutput {f.suffix} sha256 {hashlib.sha256(f.read_bytes()).hexdigest()}"
                   for f in sorted(out_dir.glob("p.*")))


CAMPAIGNS = {
    # name: (input key, file suffix, argv given the mutated path and an output dir)
    "mcap-replay": ("mcap", ".mcap", lambda p, o: ["replay", str(p), "--json"]),
    "mcap-export": ("mcap", ".mcap", lambda p, o: ["export", str(p), "--csv", str(o / "p.csv")]),
    # an .lvx carries no tracker configuration: replay takes the daemon config's (its space of interest)
    "lvx-replay": ("lvx", ".lvx", lambda p, o: ["replay", str(p), "--json", "--tracker-config",
                                                str(o.parent / "tracker.toml")]),
    "scene": ("scene", ".toml", lambda p, o: ["simulate", str(p), "--duration", "1"]),
    "config": ("config", ".toml", lambda p, o: ["daemon", "--config", str(p), "--check"]),
}


def normaliser(name: str):
    if name == "mcap-export":
        return lambda out: _drop_paths(out) + "|" + out.split(" points")[0]
    if name.endswith("replay"):
        import json

        def norm(out):
            try:
                d = json.loads(out)
            except ValueError:
                return out
            d.pop("path", None)
            d.get("comparison", {}).pop("metadata_checksum", None)
            return json.dumps(d, sort_keys=True)
        return norm
    return _drop_paths


# the trials per campaign of the issue's table (issue 32), run on 802524f
ISSUE_TRIALS = {"mcap-replay": 2371, "mcap-export": 2371, "lvx-replay": 6524, "scene": 6009, "config": 17913}


def print_table(table: dict, header: str, file=sys.stdout) -> None:
    print(header, file=file)
    print("| campaign | trials | " + " | ".join(OUTCOMES) + " |", file=file)
    print("|---|---|" + "---|" * len(OUTCOMES), file=file)
    for name, (k, c) in table.items():
        print(f"| {name} | {k} | " + " | ".join(str(c[o]) for o in OUTCOMES) + " |", file=file, flush=True)


def print_table_from_logs(paths: list[str], file=sys.stdout) -> None:
    """The table of ``--log`` files: per campaign, the trials logged (a trial logged twice, by two runs
    of the same seed, is counted once: its first line) and the median seconds per trial."""
    seen, table, secs = set(), {}, {}
    for path in paths:
        for line in open(path):
            name, k, outcome, _rc, wall, *cpu = line.rstrip("\n").split("\t")
            if (name, k) in seen:
                continue
            seen.add((name, k))
            counts = table.setdefault(name, [0, dict.fromkeys(OUTCOMES, 0)])
            counts[0] += 1
            counts[1][outcome] += 1
            secs.setdefault(name, []).append((float(wall), float(cpu[0]) if cpu else math.nan))
    ordered = {n: tuple(table[n]) for n in CAMPAIGNS if n in table}
    print_table(ordered, f"from {', '.join(Path(p).name for p in paths)}", file)
    print("", file=file)
    print("| campaign | median wall s per trial | median CPU s per trial | the issue's trials | "
          "their CPU time [h] |", file=file)
    print("|---|---|---|---|---|", file=file)
    for n in ordered:
        wall, cpu = (float(np.nanmedian(c)) if not np.all(np.isnan(c)) else math.nan for c in zip(*secs[n]))
        print(f"| {n} | {wall:.2f} | {cpu:.2f} | {ISSUE_TRIALS[n]} | {ISSUE_TRIALS[n] * cpu / 3600:.1f} |", file=file)


def _read_log(path: str) -> dict:
    out = {}
    for line in open(path):
        name, k, outcome, *_ = line.rstrip("\n").split("\t")
        out.setdefault((name, int(k)), outcome)
    return out


def print_agreement(log_a: str, log_b: str, file=sys.stdout) -> int:
    """Per campaign: the trials both logs hold and how many got the same outcome; 1 if any did not."""
    a, b = _read_log(log_a), _read_log(log_b)
    both = sorted(set(a) & set(b), key=lambda nk: (list(CAMPAIGNS).index(nk[0]), nk[1]))
    print(f"| campaign | trials in both | same outcome | differ |  ({Path(log_a).name} vs {Path(log_b).name})",
          file=file)
    print("|---|---|---|---|", file=file)
    for name in CAMPAIGNS:
        ks = [nk for nk in both if nk[0] == name]
        if ks:
            same = sum(a[nk] == b[nk] for nk in ks)
            print(f"| {name} | {len(ks)} | {same} | {len(ks) - same} |", file=file)
    differ = [nk for nk in both if a[nk] != b[nk]]
    for nk in differ:
        print(f"{nk[0]} trial {nk[1]}: {a[nk]} vs {b[nk]}", file=file)
    return 1 if differ else 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=None,
                    help="wall time over all campaigns (default 1, or no limit with --trials)")
    ap.add_argument("--trials", metavar="N|issue", default=None,
                    help="trials per campaign (a number, or 'issue': the counts of issue 32's table); "
                         "with --minutes the campaign also stops at its share of the time")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--campaign", action="append", choices=sorted(CAMPAIGNS), help="default: all")
    ap.add_argument("--mode", choices=("inprocess", "subprocess"), default="inprocess",
                    help="inprocess: the CLI's main in a forked child (fast, default); subprocess: "
                         "python -m foveatrack per trial")
    ap.add_argument("--keep", metavar="DIR", help="keep the inputs of tracebacks, hangs, memory errors and "
                                                  "silent differences")
    ap.add_argument("--table", metavar="FILE", help="also write the table there after every campaign")
    ap.add_argument("--log", metavar="FILE", help="append one line per trial: campaign, trial, outcome, "
                                                 "rc, wall seconds, CPU seconds (to compare the two modes "
                                                 "trial by trial)")
    ap.add_argument("--timeout-s", type=float, default=TIMEOUT_S, help="CPU seconds a trial may take")
    ap.add_argument("--wall-s", type=float, default=WALL_S, help="wall seconds a trial may take")
    ap.add_argument("--start", type=int, default=0, metavar="K",
                    help="begin at trial K (the mutations before it are made and dropped: a run resumed)")
    ap.add_argument("--from-log", metavar="FILE", nargs="+",
                    help="print the table of the trials these --log files hold (runs of one campaign split "
                         "over processes), the median seconds per trial beside it, and run nothing")
    ap.add_argument("--agree", metavar=("LOG_IN", "LOG_SUB"), nargs=2,
                    help="compare two --log files trial by trial (an in-process and a subprocess run of one "
                         "seed): the trials both hold, how many got the same outcome, each that did not; "
                         "run nothing")
    a = ap.parse_args()
    if a.agree:
        return print_agreement(*a.agree)
    if a.from_log:
        print_table_from_logs(a.from_log)
        return 0
    names = a.campaign or list(CAMPAIGNS)
    minutes = a.minutes if a.minutes is not None else (None if a.trials else 1.0)
    work = Path(tempfile.mkdtemp(prefix="foveatrack-fuzz-"))
    keep = Path(a.keep) if a.keep else None
    if keep:
        keep.mkdir(parents=True, exist_ok=True)
    header = (f"seed {a.seed}, mode {a.mode}, " + (f"{minutes:g} min, " if minutes else "")
              + f"limits {AS_LIMIT_BYTES >> 30} GiB address space, {a.timeout_s:g} s CPU, {a.wall_s:g} s wall"
              + (f", from trial {a.start}" if a.start else ""))
    table = {}
    log = open(a.log, "a") if a.log else None
    try:
        inputs = make_inputs(work)
        (work / "tracker.toml").write_text(inputs["config"] or "")
        budget_s = math.inf if minutes is None else minutes * 60.0 / len(names)
        for name in names:
            n_max = math.inf if a.trials is None else ISSUE_TRIALS[name] if a.trials == "issue" else int(a.trials)
            key, suffix, argv = CAMPAIGNS[name]
            base = inputs[key]
            if base is None:
                print(f"{name}: no intact input (no example daemon config)", file=sys.stderr)
                continue
            # the campaign's place in CAMPAIGNS, not in this selection: one campaign run alone mutates as in all
            rng = np.random.default_rng([a.seed, list(CAMPAIGNS).index(name)])
            out_dir = work / name
            out_dir.mkdir()
            intact = out_dir / f"intact{suffix}"
            (intact.write_text if isinstance(base, str) else intact.write_bytes)(base)
            kind, rc, baseline = trial(argv(intact, out_dir), a.timeout_s, a.mode, a.wall_s)
            baseline += output_digests(out_dir)
            if (kind, rc) != ("ok", 0):     # every trial would be measured against a failure
                print(f"{name}: the intact input itself ends in {kind}, rc {rc}: {baseline.strip()[-300:]}",
                      file=sys.stderr, flush=True)
                return 1
            norm = normaliser(name)
            counts = dict.fromkeys(OUTCOMES, 0)
            t_end = time.monotonic() + budget_s
            for _ in range(a.start):        # the same mutations as a run from trial 0 would make
                mutate_toml(base, rng) if isinstance(base, str) else mutate_bytes(base, rng)
            k = a.start
            while k < n_max and time.monotonic() < t_end:
                data = mutate_toml(base, rng) if isinstance(base, str) else mutate_bytes(base, rng)
                p = out_dir / f"t{suffix}"
                (p.write_text if isinstance(data, str) else p.write_bytes)(data)
                for f in out_dir.glob("p.*"):
                    f.unlink()
                t0 = time.monotonic()
                kind, rc, out = trial(argv(p, out_dir), a.timeout_s, a.mode, a.wall_s)
                out += output_digests(out_dir)
                outcome = classify(kind, rc, out, baseline, norm)
                counts[outcome] += 1
                if log:
                    print(f"{name}\t{k}\t{outcome}\t{rc}\t{time.monotonic() - t0:.3f}\t{LAST_CPU_S[0]:.3f}",
                          file=log, flush=True)
                if keep and outcome in ("traceback", "hang", "memory error", "silent difference"):
                    shutil.copy(p, keep / f"{name}-seed{a.seed}-trial{k}{suffix}")
                    (keep / f"{name}-seed{a.seed}-trial{k}.txt").write_text(out)
                k += 1
                if k % 20 == 0:
                    print(f"{name}: {k} trials {counts}", file=sys.stderr, flush=True)
            table[name] = (k - a.start, counts)
            if a.table:
                with open(a.table, "w") as fh:
                    print_table(table, header, fh)
    finally:
        shutil.rmtree(work, ignore_errors=True)
        if log:
            log.close()
    print_table(table, header)
    return 0


if __name__ == "__main__":
    sys.exit(main())
