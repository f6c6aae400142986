"""The command line: help everywhere, one-line errors, and end-to-end runs checked with numbers."""

from __future__ import annotations

import importlib
import json
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from evo.core.geometry import umeyama_alignment

from sonarslam.datasets.errors import DataWarning
from sonarslam.datasets.rosbag import BAG_KINDS
from sonarslam.datasets.simulator import KINDS, simulate
from sonarslam.datasets.simulator.bluerov import NAV_KINDS
from sonarslam.datasets.source import MARINA_DOCS, open_dataset
from sonarslam.slam.cli.common import POSES
from sonarslam.slam.cli.main import build_parser, main
from sonarslam.slam.cli.parsers import (
    BACKENDS,
    BLUEROV_NAV_KINDS,
    COMMANDS,
    EXTRACTOR_PRESETS,
    SIM_DURATION_S,
    WORLDS,
)
from sonarslam.slam.cli.parsers import BAG_KINDS as PARSER_BAG_KINDS
from sonarslam.slam.eval.ate import ate_against_gps
from sonarslam.slam.eval.truth import truth_trajectory
from sonarslam.slam.io.trajectory import Trajectory, read_tum
from sonarslam.slam.run.demo import SIM_DURATION_S as DEMO_SIM_DURATION_S
from sonarslam.slam.run.demo import demo_source
from sonarslam.slam.run.presets import EXTRACTOR_PRESETS as PRESETS
from sonarslam.slam.run.presets import SettingError, check_settings, run_config
from sonarslam.slam.run.run import RunResult, backend_names, results_table
from sonarslam.slam.run.sources import POSE_SOURCES, dead_reckoning_trajectory
from tests.test_docs import anchors


@pytest.fixture(scope="module")
def short_harbour(tmp_path_factory):
    return simulate(
        "harbour", seed=3, out_dir=tmp_path_factory.mktemp("sim") / "h3", duration_s=200.0
    )


def test_every_command_has_help(capsys):
    parser = build_parser()
    commands = parser._subparsers._group_actions[0].choices  # type: ignore[union-attr]
    assert {"simulate", "run", "plot-scans", "calibrate", "info", "demo", "extract"} <= set(
        commands
    )
    takes_source = {"run", "plot-scans", "extract", "calibrate", "info"}
    for name in commands:
        with pytest.raises(SystemExit) as exc:
            main([name, "--help"])
        assert exc.value.code == 0
        out = " ".join(capsys.readouterr().out.split())  # argparse's line breaks undone
        assert "usage: sonarslam " + name in out
        # the SOURCE epilog where a SOURCE is taken only (a review: demo's and report's too)
        assert ("a SOURCE is" in out) == (name in takes_source), name
        assert "SONARSLAM_DATA" in out or name in ("simulate", "report", "sweep"), name
        # --span's --loop clause where --loop is (a review: extract, plot-scans and info too)
        span = out[out.index("--span T0,T1") :] if "--span T0,T1" in out else ""
        assert ("--loop times then count from T0" in span) == (name == "run"), name
    with pytest.raises(SystemExit):
        main(["--help"])
    out = " ".join(capsys.readouterr().out.split())
    said = out[out.index("simulate simulate") : out.index("run run a back end")]
    assert "ROS bag" in said and "Ping Viewer" in said and "BlueROV2" in said, said


#: A shortest command line of each command (its required arguments only).
SHORTEST = {
    "simulate": ["pool", "--out", "o"],
    "run": ["src", "--out", "o"],
    "plot-scans": ["src"],
    "extract": ["src", "--out", "o"],
    "demo": [],
    "calibrate": ["src"],
    "info": ["src"],
    "report": ["run_dir", "--out", "o"],
    "sweep": ["--out", "o"],
}


def test_every_command_takes_quiet(capsys):
    """The README: "Every command has ``--help``; ``--quiet`` turns the progress bars off" (a
    review: report, info, simulate and plot-scans refused it)."""
    parser = build_parser()
    commands = parser._subparsers._group_actions[0].choices  # type: ignore[union-attr]
    assert set(SHORTEST) == set(commands)
    for name, argv in SHORTEST.items():
        assert parser.parse_args([name, *argv, "--quiet"]).quiet, name
        assert not parser.parse_args([name, *argv]).quiet, name
        with pytest.raises(SystemExit):
            main([name, "--help"])
        out = " ".join(capsys.readouterr().out.split())
        said = out[out.index("--quiet ") :]
        assert said.startswith("--quiet no progress bars") or said.startswith(
            "--quiet accepted as by every command; this one draws no progress bars"
        ), name


def test_an_unknown_argument_is_said_by_its_command(capsys):
    """argparse says an unrecognised argument as the top-level parser ("sonarslam: error"); the
    command's own parser says it, naming the command and its --help."""
    for name in ("report", "simulate", "run"):
        with pytest.raises(SystemExit) as exit_:
            main([name, *SHORTEST[name], "--bogus"])
        assert exit_.value.code == 2
        err = capsys.readouterr().err.strip()
        assert err == (
            f"sonarslam {name}: error: unrecognized arguments: --bogus"
            f" (see sonarslam {name} --help)"
        )


#: What ``--version`` and ``--help`` must not import: each costs seconds on the 2-core machine
#: (the whole library imported 2,295 modules in 7.7-14 s; benchmarks/cli_startup.py times it).
HEAVY = ("gtsam", "numba", "matplotlib", "scipy", "pandas", "dask", "distributed", "evo", "shapely")


def _imported_after(code: str) -> dict[str, object]:
    """Run ``code`` in a fresh interpreter; the top-level packages it left in ``sys.modules``
    and what it printed."""
    probe = (
        "import contextlib, io, json, sys\n"
        "out = io.StringIO()\n"
        f"with contextlib.redirect_stdout(out):\n    {code}\n"
        "print(json.dumps({'modules': sorted({m.split('.')[0] for m in sys.modules}),"
        " 'n': len(sys.modules), 'out': out.getvalue()}))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True, timeout=120
    )
    return json.loads(done.stdout)  # type: ignore[no-any-return]


def test_version_and_help_import_nothing_heavy():
    """``sonarslam --version``, ``--help`` and every ``COMMAND --help`` build the parsers from
    argparse alone: the library (and its gtsam, numba, matplotlib, ...) is imported only by the
    command that runs."""
    calls = [["--version"], ["--help"], *([name, "--help"] for name, _, _ in COMMANDS)]
    code = (
        "from sonarslam.slam.cli.main import main\n"
        f"    for argv in {calls!r}:\n"
        "        try:\n            main(argv)\n"
        "        except SystemExit as exc:\n            assert exc.code == 0, (argv, exc.code)"
    )
    seen = _imported_after(code)
    assert set(HEAVY).isdisjoint(seen["modules"]), set(HEAVY) & set(seen["modules"])
    assert "sonarslam.slam.run" not in seen["modules"]
    assert str(seen["out"]).startswith("sonarslam ") and "usage: sonarslam sweep" in seen["out"]
    assert int(seen["n"]) < 400  # the library imported 2,295


def test_the_parsers_offer_the_registries_choices():
    """The parsers spell out the registries' names (so that they import nothing); the same."""
    assert POSES == tuple(sorted(POSE_SOURCES))
    assert BACKENDS == tuple(backend_names())
    assert EXTRACTOR_PRESETS == tuple(sorted(PRESETS))
    assert WORLDS == KINDS
    assert PARSER_BAG_KINDS == BAG_KINDS
    assert BLUEROV_NAV_KINDS == NAV_KINDS
    assert SIM_DURATION_S == DEMO_SIM_DURATION_S
    # and every command module runs: its command(args) is there
    for name, _, module in COMMANDS:
        assert callable(importlib.import_module(module).command), name


def test_a_sweep_without_dask_names_the_extra(tmp_path, capsys, monkeypatch):
    """Without dask (``sys.modules[name] = None``: its import fails as if it were not installed)
    a sweep on Dask says which extra to install, in one line, exit 1, before it simulates."""
    monkeypatch.setitem(sys.modules, "dask.distributed", None)
    argv = ["sweep", "--seeds", "0", "--world", "harbour", "--out", str(tmp_path / "o")]
    assert main(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        "sonarslam sweep: error: a sweep on Dask needs dask, which is not installed:"
        " pip install 'sonarslam[sweep]' (in a clone of the repository: make venv, or pip"
        " install -e '.[sweep]')"
    ]
    assert not (tmp_path / "o" / "sim").exists()


def test_a_drawn_world_without_shapely_names_the_extra(tmp_path):
    """Without shapely the simulator still imports (its fixed worlds do not need it) and a drawn
    world says which extra to install, in one line, exit 1 (a fresh interpreter: shapely is
    blocked before anything imports it)."""
    code = (
        "import sys; sys.modules['shapely'] = None\n"
        "from sonarslam.slam.cli.main import main\n"
        f"sys.exit(main(['simulate', 'drawn', '--out', {str(tmp_path / 'o')!r}]))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=tmp_path
    )
    assert done.returncode == 1, done.stderr
    assert done.stderr.strip().splitlines() == [
        "sonarslam simulate: error: a drawn world needs shapely, which is not installed:"
        " pip install 'sonarslam[sim]' (in a clone of the repository: make venv, or pip install"
        " -e '.[sim]')"
    ]


def test_each_warning_is_printed_once_per_command(monkeypatch, capsys):
    """A data warning is printed once however often the command meets it (the demo opens its
    dataset for each run: its DVL gap was printed four times), on one line."""

    def command(args):
        for text in ("a.log: 1 gap of the DVL\n  longer", "a.log: 1 gap of the DVL longer"):
            warnings.warn(text, DataWarning, stacklevel=1)
        warnings.warn("b.log: another", DataWarning, stacklevel=1)
        return 0

    monkeypatch.setattr(importlib.import_module("sonarslam.slam.cli.info"), "command", command)
    assert main(["info", "anything"]) == 0
    assert capsys.readouterr().err.splitlines() == [
        "warning: a.log: 1 gap of the DVL longer",
        "warning: b.log: another",
    ]


def _result(backend, metrics, others=()):
    t = np.array([0.0, 1.0])
    tr = Trajectory(t, np.zeros((2, 3)))
    return RunResult(
        backend, tr, {"backend": backend, **metrics}, trajectories=dict.fromkeys(others, tr)
    )


def test_the_demo_table_is_against_the_truth_on_simulated_runs():
    """On simulated runs the table's figures are against the simulator's truth (its heading
    says so), then against the simulated GPS; on real data against GPS over both spans."""
    sim = {
        "ate_truth_mean_m": 1.04, "ate_truth_max_m": 1.73,
        "ate_truth_aligned_mean_m": 0.08, "ate_truth_aligned_max_m": 0.2,
        "ate_truth_smoothed_mean_m": 0.9, "ate_truth_smoothed_max_m": 1.5,
        "ate_truth_aligned_smoothed_mean_m": 0.07, "ate_truth_aligned_smoothed_max_m": 0.3,
        "ate_mean_m": 1.31, "ate_max_m": 3.28, "ate_aligned_mean_m": 0.87,
        "ate_mean_smoothed_m": 1.3, "ate_max_smoothed_m": 3.48, "ate_aligned_mean_smoothed_m": 0.86,
        "ate_sonar_mean_m": 1.31, "ate_sonar_max_m": 3.28,
    }  # fmt: skip
    lines = results_table([_result("isam2", sim, ["smoothed"])]).splitlines()
    assert lines[0].split("|")[2].strip() == "truth mean / max (m)"
    assert lines[0].split("|")[4].strip() == "simulated GPS mean / max (m)"
    assert [c.strip() for c in lines[2].split("|")[1:-1]] == [
        "isam2 online", "1.04 / 1.73", "0.08 / 0.20", "1.31 / 3.28", "0.87",
    ]  # fmt: skip
    assert [c.strip() for c in lines[3].split("|")[1:-1]] == [
        "isam2 smoothed", "0.90 / 1.50", "0.07 / 0.30", "1.30 / 3.48", "0.86",
    ]  # fmt: skip
    real = {k: v for k, v in sim.items() if "truth" not in k}
    real |= {"ate_sonar_aligned_mean_m": 0.5, "ate_sonar_aligned_max_m": 0.9}
    lines = results_table([_result("ekf", real)]).splitlines()
    assert lines[0].split("|")[2].strip() == "sonar span mean / max (m)"
    assert [c.strip() for c in lines[2].split("|")[1:-1]] == [
        "ekf", "1.31 / 3.28", "0.50 / 0.90", "1.31 / 3.28", "0.87",
    ]  # fmt: skip


def test_known_errors_are_one_line_and_exit_1(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("SONARSLAM_DATA", raising=False)
    assert (
        main(["run", str(tmp_path / "nowhere"), "--backend", "dr", "--out", str(tmp_path / "o")])
        == 1
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nowhere: no such file or directory" in err[0]
    assert main(["info", "marina"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "needs $SONARSLAM_DATA" in err[0]
    # where the data comes from and the layout SONARSLAM_DATA must point above, in that line
    assert "StPereDataset.zip" in err[0] and "marina/logs/" in err[0]
    assert "marina/keyframes/" in err[0]
    # the section that says how to get it (it left the README for docs/data.md)
    assert "see docs/data.md#the-marina-getting-the-data" in err[0]


def test_the_marina_hints_point_at_a_section_that_exists(monkeypatch):
    page, _, anchor = MARINA_DOCS.partition("#")
    assert anchor in anchors(Path(__file__).resolve().parents[1] / page)
    # `make run` without the marina says where to get it, at the same place
    monkeypatch.delenv("SONARSLAM_DATA", raising=False)
    assert f"how to get the marina: {MARINA_DOCS}" in demo_source().description


def test_unknown_backend_is_a_usage_error_naming_the_choices(short_harbour, tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["run", str(short_harbour), "--backend", "kalman", "--out", str(tmp_path / "o")])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "invalid choice: 'kalman'" in err and "'isam2'" in err
    assert not (tmp_path / "o").exists()


def test_run_dr_writes_what_it_measured(short_harbour, tmp_path):
    out = tmp_path / "dr"
    assert main(["run", str(short_harbour), "--backend", "dr", "--out", str(out), "--quiet"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    for key in (
        "ate_mean_m",
        "ate_sd_m",
        "ate_min_m",
        "ate_max_m",
        "ate_rmse_m",
        "wall_s",
        "data_s",
        "realtime_factor",
    ):
        assert key in metrics
    ds = open_dataset(short_harbour)
    expected = ate_against_gps(dead_reckoning_trajectory(ds), ds.gps)
    assert metrics["ate_mean_m"] == pytest.approx(expected.ate_mean_m, rel=1e-9)
    # the sonar span (first to last beam) beside the whole run; the simulator's truth too
    span = ds.sonar_span_s
    assert metrics["sonar_span_s"] == pytest.approx(list(span), abs=1e-9)
    sonar = ate_against_gps(dead_reckoning_trajectory(ds), ds.gps, span)
    assert metrics["ate_sonar_mean_m"] == pytest.approx(sonar.ate_mean_m, rel=1e-9)
    assert metrics["ate_sonar_n"] <= metrics["ate_n"]
    assert 0.0 < metrics["ate_truth_aligned_mean_m"] <= metrics["ate_truth_mean_m"]
    # the TUM file holds the same trajectory (to the file's precision)
    # dr.tum holds the trajectory at its own times and, interpolated, at every GPS fix and
    # true pose inside it (to the file's precision)
    tum = read_tum(out / "dr.tum")
    dr = dead_reckoning_trajectory(ds)
    own = np.isin(np.round(tum.t_s, 4), np.round(dr.t_s, 4))
    assert own.sum() == dr.t_s.size
    assert np.allclose(tum.poses_wTb[own, :2], dr.poses_wTb[:, :2], atol=1e-3)
    assert np.allclose(tum.poses_wTb[:, :2], dr.poses(tum.t_s)[:, :2], atol=1e-3)
    gps_t = read_tum(out / "gps.tum").t_s
    assert np.isin(np.round(gps_t, 4), np.round(tum.t_s, 4)).all()
    assert (out / "report.png").stat().st_size > 10_000
    assert (out / "consistency.png").stat().st_size > 10_000  # the NEES against the truth


@pytest.fixture(scope="module")
def ekf_default(short_harbour, tmp_path_factory):
    """``sonarslam run`` of the short harbour with EKF and the default settings: the folder it
    wrote, read by the tests that need this run (one run of the module instead of two)."""
    out = tmp_path_factory.mktemp("ekf-default") / "ekf"
    assert main(["run", str(short_harbour), "--backend", "ekf", "--out", str(out), "--quiet"]) == 0
    return out


def test_run_ekf_maps_the_true_walls(short_harbour, ekf_default):
    out = ekf_default
    metrics = json.loads((out / "metrics.json").read_text())
    landmarks = json.loads((out / "map.json").read_text())["landmarks"]
    assert metrics["landmarks"] == len(landmarks) >= 3
    assert (out / "consistency.png").stat().st_size > 10_000  # NEES and the NIS of each kind
    assert metrics["assoc_associated"] > 0.5 * metrics["assoc_observations"]
    ds = open_dataset(short_harbour)
    offset = np.asarray(ds.truth["first_fix_enu_m"])
    walls = np.asarray(ds.truth["walls_m"]) - offset
    # a mapped landmark lies on a true wall when both its ends are within 1.5 m of the wall's
    # line and its direction within 3 deg: all those seen 3 times or more, 80 % of all. The map
    # is taken in the frame that best fits the trajectory to the truth: a rotation of the whole
    # run by the AHRS bias (2 deg) is unobservable and not the map's error
    truth = truth_trajectory(ds)
    ekf = read_tum(out / "ekf.tum")
    est, ref = ekf.poses_wTb[:, :2], truth.poses(ekf.t_s)[:, :2]
    rot, shift, _ = umeyama_alignment(est.T, ref.T, False)
    on_wall = []
    for lm in landmarks:
        ends = (rot[:2, :2] @ np.asarray(lm["endpoints"]).T).T + shift[:2]
        d = ends[1] - ends[0]
        ok = False
        for a, b in walls:
            w = (b - a) / np.linalg.norm(b - a)
            n = np.array([-w[1], w[0]])
            angle = np.degrees(np.arccos(min(1.0, abs(w @ d) / np.linalg.norm(d))))
            if np.abs((ends - a) @ n).max() < 1.5 and angle < 3.0:
                ok = True
                break
        on_wall.append(ok)
        assert ok or lm["observations"] < 3, f"landmark {lm['id']} is on no wall"
    assert np.mean(on_wall) >= 0.8
    # and the closed loop stays within a few metres of the truth
    err = np.hypot(*(ekf.poses(ekf.t_s)[:, :2] - truth.poses(ekf.t_s)[:, :2]).T)
    assert err.mean() < 3.0


def test_run_config_replaces_only_the_keys_it_gives(short_harbour, tmp_path, capsys):
    """--config: a partial sonarslam.toml on top of the dataset's own; the result is the
    dead reckoning of the dataset with that one mounting changed, and it is written out."""
    import math
    from dataclasses import replace

    from sonarslam.datasets.config import load_dataset_config

    ds = open_dataset(short_harbour)
    yaw_deg = math.degrees(ds.config.ahrs_mounting.yaw_rad) + 3.0
    override = tmp_path / "heading.toml"
    override.write_text(f"[mounting.ahrs]\nyaw_deg = {yaw_deg!r}\n")
    out = tmp_path / "dr3"
    args = ["run", str(short_harbour), "--backend", "dr", "--out", str(out), "--quiet"]
    assert main([*args, "--config", str(override)]) == 0
    used = load_dataset_config(out / "config_used.toml")
    assert math.degrees(used.ahrs_mounting.yaw_rad) == pytest.approx(yaw_deg, abs=1e-9)
    assert used.sonar_mounting == ds.config.sonar_mounting  # untouched keys kept
    assert used.dvl_mounting.yaw_rad == ds.config.dvl_mounting.yaw_rad
    turned = replace(
        ds, config=replace(ds.config, ahrs_mounting=replace(used.ahrs_mounting, source=""))
    )
    expected = ate_against_gps(dead_reckoning_trajectory(turned), ds.gps).ate_mean_m
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["ate_mean_m"] == pytest.approx(expected, rel=1e-9)
    assert metrics["ate_mean_m"] != pytest.approx(
        ate_against_gps(dead_reckoning_trajectory(ds), ds.gps).ate_mean_m, rel=1e-3
    )
    # a wrong key is named with the file
    override.write_text("[mounting.ahrs]\nyaw = 3.0\n")
    assert main([*args, "--config", str(override)]) == 1
    err = capsys.readouterr().err
    assert "heading.toml" in err and "yaw" in err


def test_run_set_changes_the_settings_it_names(short_harbour, ekf_default, tmp_path, capsys):
    """--set reaches the extractor and the back end, is recorded, and a wrong field is named."""
    out = tmp_path / "ekf-set"
    args = ["run", str(short_harbour), "--backend", "ekf", "--out", str(out), "--quiet"]
    assert main([*args, "--set", "extractor.max_range_m=3", "--set", "ekf.min_rho_m=2"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["settings"] == {"extractor.max_range_m": 3, "ekf.min_rho_m": 2}
    # walls farther than 3 m are not seen: fewer lines than with the defaults
    default = json.loads((ekf_default / "metrics.json").read_text())
    assert metrics["line_features"] < default["line_features"]
    # a setting that does not fit its field is a usage error: one line, exit 2
    assert main([*args, "--set", "ekf.no_such_field=1"]) == 2
    assert "no_such_field" in capsys.readouterr().err
    assert main([*args, "--set", "isam2.robust=cauchy"]) == 2
    assert "does not apply to back end 'ekf'" in capsys.readouterr().err


def test_info_lists_what_run_would_take_with_config_and_set(short_harbour, tmp_path, capsys):
    """info takes run's --config and --set: each value it lists is the one given, its source
    names the option; a wrong setting is refused before anything is read."""
    override = tmp_path / "offset.toml"
    override.write_text("[sonar]\nrange_offset_m = 0.25\n")
    sets = ["--set", "ekf.min_rho_m=2.5", "--set", "scans.kernel_k=2"]
    assert main(["info", str(short_harbour), "--config", str(override), *sets]) == 0
    rows = {
        line.split()[0] if not line.startswith("  [") else " ".join(line.split()[:2]): line
        for line in capsys.readouterr().out.splitlines()
        if line.startswith("  ")
    }
    assert rows["[sonar] range_offset_m"].split()[2:5] == ["0.25", "m", "offset.toml"]
    assert rows["ekf.min_rho_m"].split()[1:4] == ["2.5", "m", "--set"]
    assert rows["scans.kernel_k"].split()[1:3] == ["2.0", "--set"]
    assert rows["isam2.min_rho_m"].split()[-1] == "default"  # another scope untouched
    # a back end's noise keys are those it reads; [noise] ahrs_sigma_deg is dead reckoning's
    assert rows["ekf.noise.ahrs_white_sigma_deg"].split()[1:3] == ["1.0", "deg"]
    assert "isam2.noise.ahrs_bias_sigma_deg" in rows and "[noise] ahrs_sigma_deg" in rows
    assert not {"ekf.noise.ahrs_sigma_deg", "isam2.noise.dvl_sigma_mps"} & set(rows)
    assert main(["info", str(short_harbour), "--set", "ekf.noise.ahrs_sigma_deg=3"]) == 2
    err = capsys.readouterr().err
    assert "ekf.noise.ahrs_sigma_deg: the back end does not read it" in err
    assert "give it in a --config file" in err
    assert main(["info", str(short_harbour), "--set", "ekf.no_such_field=1"]) == 2
    captured = capsys.readouterr()
    assert "no_such_field" in captured.err and captured.out == ""


def test_scan_settings_are_taken_where_the_run_takes_scans():
    """``--set scans.*``: checked before the run and applied by run_config when the back end's
    constraints hold scans; refused with a line naming the setting otherwise."""
    given = {"isam2.constraints": "lines,scans", "scans.floor_sigma_m": 1.0}
    check_settings("isam2", given)
    config = run_config([], "isam2", given)
    assert config.scans.floor_sigma_m == 1.0
    assert config.backend.constraint_kinds == {"lines", "scans"}
    assert run_config([], "isam2").scans.floor_sigma_m == 0.15  # the preset's otherwise
    with pytest.raises(SettingError, match=r"^scans.floor_sigma_m: .*takes no scans"):
        check_settings("isam2", {"scans.floor_sigma_m": 1.0})
    with pytest.raises(SettingError, match=r"^scans.floor_sigma_m: .*takes no scans"):
        check_settings("ekf", {"scans.floor_sigma_m": 1.0})
    with pytest.raises(SettingError, match=r"^scans\.floor_sigma_mm"):
        check_settings("isam2", {"isam2.constraints": "scans", "scans.floor_sigma_mm": 1.0})
    with pytest.raises(SettingError, match=r"^scans\.floor_sigma_mm"):
        run_config([], "isam2", {"isam2.constraints": "scans", "scans.floor_sigma_mm": 1.0})
