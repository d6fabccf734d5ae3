"""`foveatrack lidar ...` as a user runs it: JSON contracts, plots, errors, the Fig. 7 sweep."""

import json

import pytest

from foveatrack.cli import main


def run_json(capsys, *argv):
    assert main(list(argv)) == 0
    return json.loads(capsys.readouterr().out)


def test_info_json_and_model_switch(capsys):
    info = run_json(capsys, "lidar", "info", "mid40", "--json")
    assert info["model"] == "exact" and info["channels"] == 1 and info["point_rate_hz"] == 100_000
    assert abs(info["fov_deg"][0] - 38.4) < 0.15
    assert info["paraxial_error_deg"][0] == pytest.approx(info["paraxial_fov_deg"][0] - info["fov_deg"][0], abs=1e-3)
    para = run_json(capsys, "lidar", "info", "mid40", "--json", "--model", "paraxial")
    assert para["model"] == "paraxial" and para["fov_deg"] == info["paraxial_fov_deg"]


@pytest.mark.slow
def test_density_and_coverage_json_and_plots(capsys, tmp_path):
    d = run_json(capsys, "lidar", "density", "prototype", "--duration", "0.5", "--json", "--plot", str(tmp_path / "d.png"))
    assert len(d["radius_edges_deg"]) == len(d["simulated"]) + 1 == len(d["analytic"]) + 1
    c = run_json(capsys, "lidar", "coverage", "prototype", "--duration", "1", "--noise", "0.01", "--json",
                 "--plot", str(tmp_path / "c.png"))
    assert c["method"] == "voxel" and len(c["times_s"]) == len(c["coverage"])
    assert 0 < c["t50_s"] < c["t90_s"] < 1.0
    assert (tmp_path / "d.png").stat().st_size > 10_000 and (tmp_path / "c.png").stat().st_size > 10_000


def test_coverage_text_says_a_level_not_reached(capsys):
    """A coverage level the run did not reach was printed as "90 % at None s"."""
    c = run_json(capsys, "lidar", "coverage", "prototype", "--duration", "0.3", "--json")
    assert c["t50_s"] is not None and c["t90_s"] is None     # the case: 50 % reached, 90 % not
    assert main(["lidar", "coverage", "prototype", "--duration", "0.3"]) == 0
    out = capsys.readouterr().out
    assert f"50 % at {c['t50_s']:.2f} s" in out and "90 % not reached in 0.3 s" in out and "None" not in out


@pytest.mark.parametrize("argv, desc, total", [
    (["density", "prototype", "--duration", "0.3"], "density:", "/60.0k"),         # both models: 2 x 30 000
    (["coverage", "prototype", "--duration", "0.1"], "voxel coverage:", "/10.0k"),
])
@pytest.mark.slow
def test_density_and_coverage_show_progress_on_stderr_unless_told_not_to(capsys, monkeypatch, argv, desc, total):
    """A long run showed nothing until it ended; the bar appears once a run has taken
    PROGRESS_DELAY_S (0 here, so that this short run counts as long)."""
    from foveatrack.cli import lidar_cmd

    monkeypatch.setattr(lidar_cmd, "PROGRESS_DELAY_S", 0.0)
    assert main(["lidar", *argv]) == 0
    out, err = capsys.readouterr()
    assert desc in err and total in err and "pts/s" in err
    assert desc not in out and "pts" not in out
    assert main(["lidar", *argv, "--no-progress"]) == 0
    assert capsys.readouterr().err == ""


def test_pattern_plot(tmp_path, capsys):
    assert main(["lidar", "pattern", "horizon", "--duration", "0.02", "--plot", str(tmp_path / "p.png")]) == 0
    assert (tmp_path / "p.png").exists()


def test_custom_optics_file_and_its_errors(tmp_path, capsys):
    good = tmp_path / "optics.toml"
    good.write_text('[lidar]\npoint_rate_hz = 50000\n[[lidar.prisms]]\nwedge_deg = 18\nindex = 1.51\nrpm = 3000\n'
                    '[[lidar.prisms]]\nwedge_deg = 18\nindex = 1.51\ntilted_face = "entry"\nrpm = -2000\n')
    info = run_json(capsys, "lidar", "info", str(good), "--json")
    assert info["point_rate_hz"] == 50_000
    bad = tmp_path / "bad.toml"
    bad.write_text('[lidar]\n[[lidar.prisms]]\nwedge_deg = 18\nindex = 1.51\nspin = 3\n')
    assert main(["lidar", "info", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "bad.toml" in err and "spin" in err
    assert main(["lidar", "info", "nosuch"]) == 2
    assert "prototype" in capsys.readouterr().err
    assert main(["lidar", "info", str(tmp_path / "missing.toml")]) == 2


def test_coverage_map_local_processes(capsys, tmp_path):
    m = run_json(capsys, "lidar", "coverage-map", "prototype", "--grid", "3", "--cap", "0.3", "--workers", "2",
                 "--no-progress", "--json", "--plot", str(tmp_path / "m.png"))
    assert len(m["t90_noise_s"]) == 3 and len(m["t90_noise_s"][0]) == 3
    assert (tmp_path / "m.png").exists()


@pytest.mark.slow
def test_coverage_map_runs_on_a_local_dask_cluster(capsys):
    import distributed  # in the [test] extra: this test must run, never skip

    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        on_dask = run_json(capsys, "lidar", "coverage-map", "prototype", "--grid", "3", "--cap", "0.3",
                           "--scheduler", cluster.scheduler_address, "--no-progress", "--json")
    local = run_json(capsys, "lidar", "coverage-map", "prototype", "--grid", "3", "--cap", "0.3", "--workers", "1",
                     "--no-progress", "--json")
    assert on_dask["scheduler"].startswith("tcp://")
    assert on_dask["t90_noise_s"] == local["t90_noise_s"] and on_dask["t90_clean_s"] == local["t90_clean_s"]


@pytest.mark.slow
def test_unreachable_scheduler_is_a_clear_error(capsys):
    assert main(["lidar", "coverage-map", "prototype", "--grid", "2", "--cap", "0.1", "--no-progress",
                 "--scheduler", "tcp://127.0.0.1:9"]) == 2
    assert "Dask scheduler" in capsys.readouterr().err


@pytest.mark.parametrize("argv", [
    ["lidar", "coverage-map", "prototype", "--rpm1", "1000:70000", "--grid", "2", "--no-progress"],
    ["lidar", "coverage-map", "prototype", "--rpm1", "nan:5", "--grid", "2", "--no-progress"],
    ["lidar", "pattern", "mid40", "--duration", "1e-9"],
    ["lidar", "density", "mid40", "--bins", "0"],
    ["lidar", "density", "mid40", "--duration", "1e-6"],
])
def test_lidar_cli_mistakes_exit_2_with_a_message(capsys, argv):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("foveatrack: error:") and "Traceback" not in err


def test_optics_files_with_wrong_types_are_clear_errors(tmp_path, capsys):
    for text in ("lidar = 5\n", "[lidar]\nprisms = 3\n",
                 "[lidar]\nchannel_offsets_deg = 5\n[[lidar.prisms]]\nwedge_deg = 18\nindex = 1.5\n"
                 "[[lidar.prisms]]\nwedge_deg = 18\nindex = 1.5\n"):
        path = tmp_path / "o.toml"
        path.write_text(text)
        assert main(["lidar", "info", str(path)]) == 2
        err = capsys.readouterr().err
        assert "o.toml" in err and "Traceback" not in err


def test_coverage_map_keeps_cells_whose_speeds_repeat_after_rounding():
    import numpy as np

    from sim.scan.coverage_map import coverage_map
    from sim.scan.presets import PRESETS
    from sim.sweep import make_executor

    with make_executor(workers=1) as ex:
        m = coverage_map(PRESETS["prototype"], np.linspace(7000, 7001, 3), np.array([-4664.0]), 0.05, ex, progress=False)
    assert not np.isnan(m.t90_clean_s).any() and not np.isnan(m.t90_noise_s).any()


@pytest.mark.parametrize("preset, fov, message", [
    ("mid70", "70.40 x 70.40", None),
    ("avia", "70.40 x 77.20", "6 channels"),
    ("tele15", "14.50 x 16.20", "6 channels"),
    ("mid100", "98.43 x 38.43", "3 heads"),
])
def test_livox_presets_in_lidar_info_and_density(capsys, preset, fov, message):
    assert main(["lidar", "info", preset]) == 0
    assert f"{preset}: FoV {fov} deg (exact model)" in capsys.readouterr().out
    if message:   # eq. (4) is one beam's radial law: several lasers or heads are refused, named
        assert main(["lidar", "density", preset, "--duration", "0.05", "--no-progress"]) == 2
        assert message in capsys.readouterr().err


def test_lidar_info_says_a_pattern_that_repeats_after_1e9_s_in_words(capsys):
    # "pattern repeats every None s" (repeat_period_s is None past 1e9 s)
    from foveatrack.cli import main

    assert main(["lidar", "info", "horizon"]) == 0
    out = capsys.readouterr().out
    assert "None" not in out and "repeats only after more than 1e9 s" in out
