"""The route that regenerates one section of the study's report (``--axis effects|objects``), as the
tests of both axes drive it: from a copy of the committed results, the axis's record back, every other
axis and the meta as they were, and the page the one ``--from-json`` writes from the same results."""

import json
import shutil
from pathlib import Path

from foveatrack.cli import main

DOCS = Path(__file__).resolve().parents[2] / "docs"


def run_one_axis(tmp_path, axis: str, *args: str) -> tuple[dict, str]:
    """Run ``study accuracy-vs-time --axis AXIS ARGS`` on a copy of docs' results in ``tmp_path``;
    returns the axis's new record and the page."""
    shutil.copy(DOCS / "accuracy-vs-time.json", tmp_path / "accuracy-vs-time.json")
    before = json.loads((tmp_path / "accuracy-vs-time.json").read_text())
    assert main(["study", "accuracy-vs-time", "--axis", axis, *args, "--out", str(tmp_path), "--no-progress"]) == 0
    after = json.loads((tmp_path / "accuracy-vs-time.json").read_text())
    record = after["results"]["axes"].pop(axis)
    before["results"]["axes"].pop(axis, None)
    assert after == before                      # every other axis and the meta: as they were
    text = (tmp_path / "accuracy-vs-time.md").read_text()
    other = tmp_path / "again"
    assert main(["study", "accuracy-vs-time", "--from-json", str(tmp_path / "accuracy-vs-time.json"),
                 "--out", str(other)]) == 0
    assert (other / "accuracy-vs-time.md").read_text() == text
    return record, text
