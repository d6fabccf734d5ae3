"""A writer cut short as a Ctrl-C cuts it: an ``open`` for a module under test whose files raise
KeyboardInterrupt once ``after`` bytes have gone out (the writes before it reach the file), for the
tests that an interrupted export leaves nothing under its name (:mod:`foveatrack.atomic_file`)."""

import builtins


class _CutShort:
    def __init__(self, fh, budget):
        self._fh, self._budget = fh, budget

    def write(self, data):
        if self._budget[0] < len(data):
            self._fh.write(data[:self._budget[0]])
            self._budget[0] = 0
            raise KeyboardInterrupt
        self._budget[0] -= len(data)
        return self._fh.write(data)

    def __getattr__(self, name):
        return getattr(self._fh, name)

    def __iter__(self):
        return iter(self._fh)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._fh.close()


def cut_short_open(after: int):
    """An ``open`` (monkeypatch it into the writing module) whose writes stop with KeyboardInterrupt
    after ``after`` bytes (characters, in text mode) in all."""
    budget = [after]

    def _open(*args, **kwargs):
        return _CutShort(builtins.open(*args, **kwargs), budget)

    return _open
