"""``foveatrack recover RECORDING``: complete a recording cut short (kill -9, power loss) from its
command journal (:mod:`foveatrack.daemon.recover`).  A recording closed properly is left alone
(said so); a damaged journal line is named and skipped."""

from __future__ import annotations


def register(sub) -> None:
    p = sub.add_parser("recover", help="complete a daemon recording cut short (kill -9) from its command journal")
    p.add_argument("recording", metavar="RECORDING", nargs="+",
                   help="a daemon .mcap recording; its journal is RECORDING.commands.jsonl beside it")
    p.set_defaults(func=cmd_recover)


def cmd_recover(args) -> int:
    import sys

    from foveatrack.daemon.recover import head_after_a_kill, recover

    for path in args.recording:
        res = recover(path, progress=lambda n: print(f"  {n} frames copied", file=sys.stderr, flush=True))
        for line in res.bad_lines:
            print(f"WARNING: {line}", file=sys.stderr)
        if res.reader_problem:
            print(f"note: what the cut-short file lost: {res.reader_problem}", file=sys.stderr)
        print(res.describe())
        if res.recovered:
            # the daemon says this at its next start only when it completes the recording itself
            print(f"WARNING: the run that wrote {path} was killed: {head_after_a_kill()}", file=sys.stderr)
    return 0
