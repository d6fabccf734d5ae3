"""The regression corpus of damaged and hostile files (issue 32, ``tests/corpus``, made by
``scripts/make_fuzz_corpus.py``): every file through the real CLI (``foveatrack.cli.main``) in a
forked child under the fuzz harness's limits (4 GiB of address space, a timeout), as
``scripts/fuzz_files.py`` runs its trials.  Each must end as its entry says and never otherwise:

* ``error``: rc 2 and one line ``foveatrack: error: ...`` (naming what was wrong, ``match``);
* ``warning``: rc 0 and a WARNING naming the loss (``match``);
* ``ok``: rc 0, a valid result (an empty recording is one);

and never a traceback, a MemoryError or a hang.  The timeout only tells a hang from an end: the
corpus files take about a second each."""

import json
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CORPUS = ROOT / "tests" / "corpus"
ENTRIES = json.loads((CORPUS / "corpus.json").read_text())
TIMEOUT_S = 300.0

sys.path.insert(0, str(ROOT / "scripts"))
sys.path.insert(0, str(ROOT / "tests" / "daemon"))
import fuzz_files  # noqa: E402  - the harness's trial: the CLI in a forked child under its limits
from daemon_procs import free_udp_port  # noqa: E402


@pytest.fixture(scope="module", autouse=True)
def warm_kernels(tmp_path_factory):
    """Replay the intact files once here, so each forked child finds the kernels compiled."""
    out = tmp_path_factory.mktemp("warm")
    fuzz_files.run_cli(["replay", str(CORPUS / "intact.mcap"), "--json"])
    fuzz_files.run_cli(["replay", str(CORPUS / "intact.lvx"), "--json", "--tracker-config",
                        str(CORPUS / "daemon.toml")])
    fuzz_files.run_cli(["export", str(CORPUS / "intact.mcap"), "--csv", str(out / "p.csv")])


def test_the_corpus_is_small():
    assert sum(f.stat().st_size for f in CORPUS.iterdir()) < 1_000_000
    assert {e["file"] for e in ENTRIES} <= {f.name for f in CORPUS.iterdir()}


@pytest.mark.parametrize("entry", ENTRIES, ids=[f"{e['file']}:{e['argv'][0]}:{'-'.join(e['argv'][2:4])}"
                                                for e in ENTRIES])
def test_corpus_file_ends_cleanly(entry, tmp_path):
    path = CORPUS / entry["file"]
    if entry["argv"][0] == "daemon" and entry["expect"] == "ok":
        path = _on_free_ports(path, tmp_path)
    argv = [a.format(file=path, out=tmp_path, corpus=CORPUS) for a in entry["argv"]]
    kind, rc, out = fuzz_files.trial(argv, TIMEOUT_S)
    assert kind == "ok", f"{entry['what']}: {kind}\n{out}"
    assert "Traceback" not in out, out
    errors = [ln for ln in out.splitlines() if ln.startswith("foveatrack: error:")]
    expect, match = entry["expect"], entry.get("match")
    if expect == "error":
        assert rc == 2 and len(errors) == 1, (entry["what"], rc, out)
        assert match is None or match in errors[0], (match, errors[0])
    elif expect == "warning":
        assert rc == 0, (entry["what"], rc, out)
        warnings = [ln for ln in out.splitlines() if "WARNING" in ln]
        assert warnings and (match is None or any(match in w for w in warnings)), (match, out[-3000:])
    else:
        assert expect == "ok"
        assert rc == 0 and not errors, (entry["what"], rc, out[-3000:])


def _on_free_ports(path: Path, tmp_path: Path) -> Path:
    """A copy of a daemon config with its lidar ports moved to free ones: ``daemon --check`` refuses
    ports something else holds (a Livox driver on 55000, another daemon, the vendor SDK's samples),
    and the corpus asks about the file, not this machine's ports."""
    text = re.sub(r"^(cmd_port|data_port|broadcast_port)( *= *)\d+",
                  lambda m: f"{m[1]}{m[2]}{free_udp_port()}", path.read_text(), flags=re.M)
    copy = tmp_path / path.name
    copy.write_text(text)
    return copy


@pytest.mark.parametrize("name,argv", [("config-nested.toml", ["daemon", "--config", "{file}", "--check"]),
                                       ("crc-zero.mcap", ["replay", "{file}", "--json"])])
def test_the_harness_tells_the_same_in_process_and_as_a_subprocess(name, argv):
    """``fuzz_files.py --mode subprocess`` (python -m foveatrack, a fresh interpreter) classifies a
    trial as the in-process mode does."""
    argv = [a.format(file=CORPUS / name) for a in argv]
    got = {}
    for mode in ("inprocess", "subprocess"):
        kind, rc, out = fuzz_files.trial(argv, TIMEOUT_S, mode)
        got[mode] = fuzz_files.classify(kind, rc, out, "", lambda text: text)
    assert got["inprocess"] == got["subprocess"] in ("clean error", "warning+partial"), got


def _spin(args):
    while True:
        pass


def _sleep(args):
    import time

    time.sleep(3600)


@pytest.mark.parametrize("body,cpu_s,wall_s,why", [(_spin, 1.0, 600.0, "over 1 s of CPU time"),
                                                   (_sleep, 600.0, 2.0, "")])
def test_a_trial_that_computes_or_waits_too_long_is_a_hang(monkeypatch, body, cpu_s, wall_s, why):
    """A hang is either limit: CPU time (a loop, told apart from a trial slowed by a busy machine) or
    wall time (a sleep); the forked child is gone after it."""
    monkeypatch.setattr(fuzz_files, "run_cli", body)
    assert fuzz_files.trial(["x"], cpu_s, "inprocess", wall_s) == ("hang", None, why)
