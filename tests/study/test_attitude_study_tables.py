"""The attitude study's mis-calibrated speed tables (issue 32): they were written to a fixed, shared
``/tmp/foveatrack-tables/<unit>-speed<scale>-accel<scale>.json``, following links, so another user
could plant a link there (and overwrite a file of ours) or a table of theirs (and change our study).
Now each process writes them into its own new directory, mode 0700."""

import os
import stat
import tempfile

import sim.attitude_study as study


def test_the_tables_go_to_a_private_directory_and_never_through_a_planted_link(tmp_path, monkeypatch):
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    monkeypatch.setattr(study, "_TABLES_DIR", None, raising=False)
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    shared = tmp_path / "foveatrack-tables"      # where the tables went: planted with links by name
    shared.mkdir()
    for scale in ("0.5", "1"):
        (shared / f"pts-303-unit0-speed{scale}-accel1.json").symlink_to(victim)
    out = study._scaled_truth_table({"gimbal": {}}, 0.5, 1.0, "test")
    assert victim.read_text() == "precious\n"
    d = os.path.dirname(out)
    assert os.path.realpath(d) != os.path.realpath(shared)
    assert stat.S_IMODE(os.stat(d).st_mode) == 0o700 and not os.path.islink(out)
    assert '"axes"' in open(out).read()
