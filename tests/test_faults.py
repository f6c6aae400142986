"""Sensor faults end to end, and the command line's misuse: every fault completes with a
warning that names it and finite outputs, or stops with a one-line error; nothing is left
half-written (README, "Bad input"; ``benchmarks/fault_injection.py`` gives the marina's table)."""

from __future__ import annotations

import json
import shutil
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from sonarslam.datasets.config import GateConfig
from sonarslam.datasets.errors import DataError, DataWarning
from sonarslam.datasets.gates import dvl_spikes
from sonarslam.datasets.source import open_dataset
from sonarslam.slam.cli.main import main
from sonarslam.slam.io.files import atomic_path, write_json
from sonarslam.slam.run.run import run_backend
from tests.fuzz_inputs import edit_log_rows

GAP = (30.0, 60.0)  # s after the first row


@pytest.fixture(scope="module")
def harbour(simulated: Callable[..., Path]) -> Path:
    """100 s of harbour, seed 4 (simulated once per session: tests/test_faults.py and
    tests/test_never_silent.py read it); read only, a test that changes it copies it."""
    return simulated("harbour", 4, 100.0, name="h")


def _copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst


def _log(folder: Path, suffix: str) -> Path:
    return next(folder.glob(f"*_{suffix}.log"))


def _open(folder: Path) -> tuple:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ds = open_dataset(folder)
    return ds, [str(w.message) for w in caught if issubclass(w.category, DataWarning)]


def _strict(path: Path) -> dict:
    def refuse(name: str) -> float:
        raise AssertionError(f"{path} holds {name}: not strict JSON")

    return json.loads(path.read_text(), parse_constant=refuse)


def test_a_dvl_gap_grows_the_covariance_and_is_reported(harbour, tmp_path):
    folder = _copy(harbour, tmp_path / "h")
    edit_log_rows(_log(folder, "DVL"), lambda t, f: [] if GAP[0] <= t <= GAP[1] else [f])
    ds, said = _open(folder)
    assert any("gap(s) of the DVL" in s and "_DVL.log" in s for s in said)
    base = run_backend(_open(harbour)[0], "dr")
    run = run_backend(ds, "dr")
    assert run.metrics["gap_dvl_count"] == base.metrics["gap_dvl_count"] + 1
    assert run.metrics["gap_dvl_longest_s"] == pytest.approx(GAP[1] - GAP[0], abs=1.5)
    t_end = ds.dvl.t[0] + GAP[1]
    var = run.trajectory.covariance(t_end)[0, 0]
    var_base = base.trajectory.covariance(t_end)[0, 0]
    # the velocity is held, then unknown (0.3 m/s): the position sigma grows by metres
    assert np.sqrt(var) > np.sqrt(var_base) + 3.0
    assert np.all(np.isfinite(run.trajectory.poses_wTb))


def test_an_ahrs_gap_is_stepped_through_with_a_growing_heading_variance(harbour, tmp_path):
    folder = _copy(harbour, tmp_path / "h")
    edit_log_rows(_log(folder, "MTi"), lambda t, f: [] if GAP[0] <= t <= GAP[1] else [f])
    ds, said = _open(folder)
    assert any("gap(s) of the AHRS" in s for s in said)
    t0 = ds.attitude.t[0]
    for backend in ("dr", "ekf"):
        run = run_backend(ds, backend, t_end_s=t0 + 80.0)
        tr = run.trajectory
        inside = (tr.t_s > t0 + GAP[0] + 1.0) & (tr.t_s < t0 + GAP[1] - 1.0)
        # poses inside the gap at the DVL's pace (~1.5 Hz), not one long step
        assert inside.sum() > 0.8 * (GAP[1] - GAP[0] - 2.0), backend
        assert np.all(np.isfinite(tr.poses_wTb)) and np.all(np.isfinite(tr.covs))
        yaw_var = tr.covs[inside, 2, 2]
        assert yaw_var[-1] > 4.0 * tr.covs[0, 2, 2], backend  # the heading grows uncertain
        assert run.metrics["gap_ahrs_count"] >= 1


def test_spikes_placeholders_and_repeats_are_dropped_and_counted(harbour, tmp_path):
    base_ds = _open(harbour)[0]
    base = run_backend(base_ds, "dr").metrics
    folder = _copy(harbour, tmp_path / "h")
    once = {"DVL": False, "DGPS": False, "MTi": False}

    def spike(suffix: str, changes: dict[int, str]):
        def edit(t: float, f: list[str]) -> list[list[str]]:
            if t > 40.0 and not once[suffix]:
                once[suffix] = True
                return [[changes.get(i, v) for i, v in enumerate(f)]]
            return [f]

        return edit

    edit_log_rows(_log(folder, "DVL"), spike("DVL", {11: "1e308"}))
    edit_log_rows(_log(folder, "DGPS"), spike("DGPS", {1: "0.0", 2: "0.0"}))
    edit_log_rows(_log(folder, "MTi"), spike("MTi", {3: "0.0"}))
    ds, said = _open(folder)
    m = run_backend(ds, "dr").metrics
    assert m["fault_dvl_speed_spikes"] == 1 and m["fault_gps_no_fix"] == 1
    assert m["fault_ahrs_heading_jumps"] in (0, 1)  # 0 only if the heading was near 0 anyway
    assert m["ate_n"] == base["ate_n"] - 1
    assert abs(m["ate_mean_m"] - base["ate_mean_m"]) < 0.5 and np.isfinite(m["ate_max_m"])
    assert len(said) >= 2 and all(str(folder) in s for s in said)
    twice = _copy(harbour, tmp_path / "twice")
    edit_log_rows(_log(twice, "DGPS"), lambda t, f: [f, f])
    m2 = run_backend(_open(twice)[0], "dr").metrics
    assert m2["ate_n"] == base["ate_n"] and m2["ate_mean_m"] == pytest.approx(base["ate_mean_m"])
    assert m2["fault_gps_repeated_stamps"] == base_ds.gps.t.size


def test_a_dvl_never_valid_is_a_one_line_error_and_leaves_nothing(harbour, tmp_path, capsys):
    folder = _copy(harbour, tmp_path / "h")
    edit_log_rows(_log(folder, "DVL"), lambda t, f: [[*f[:14], "0", *f[15:]]])
    out = tmp_path / "out"
    assert main(["run", str(folder), "--backend", "ekf", "--out", str(out), "--quiet"]) == 1
    err = [ln for ln in capsys.readouterr().err.splitlines() if not ln.startswith("warning:")]
    assert len(err) == 1 and "_DVL.log" in err[0] and "bottom lock" in err[0]
    assert not out.exists()
    with pytest.raises(DataError, match="bottom lock"):
        run_backend(_open(folder)[0], "dr")


def test_a_clock_offset_beyond_a_turn_of_the_head_is_refused(harbour, tmp_path, capsys):
    """An hour's offset (a clock in another zone) left no beam; a 150 s one (150 ms meant) ran,
    on a longer run, with a health warning at best: both are refused when the file is read,
    naming it, its line and the key."""
    config = tmp_path / "late.toml"
    out = tmp_path / "out"
    args = ["run", str(harbour), "--backend", "ekf", "--out", str(out), "--quiet"]
    for value in ("3600.0", "150", "1e9"):
        config.write_text(f"[sonar]\ntime_offset_s = {value}\n")
        assert main([*args, "--config", str(config)]) == 1
        err = [ln for ln in capsys.readouterr().err.splitlines() if not ln.startswith("warning:")]
        assert (
            len(err) == 1 and "late.toml:2: [sonar] time_offset_s: must be in [-10, 10]" in err[0]
        )
    assert not out.exists()


def test_outputs_are_strict_json_and_written_whole(tmp_path):
    path = write_json(tmp_path / "m.json", {"a": float("nan"), "b": [np.float64(np.inf), 1]})
    assert _strict(path) == {"a": None, "b": [None, 1]}
    target = tmp_path / "half.txt"
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        tmp.write_text("half")
        raise RuntimeError("the writer failed")
    assert not target.exists() and list(tmp_path.iterdir()) == [path]


def test_a_run_writes_strict_json_and_says_each_fault_on_one_line(harbour, tmp_path, capsys):
    folder = _copy(harbour, tmp_path / "h")
    edit_log_rows(_log(folder, "DGPS"), lambda t, f: [] if t > 50.0 else [f])
    out = tmp_path / "out"
    assert main(["run", str(folder), "--backend", "dr", "--out", str(out), "--quiet"]) == 0
    metrics = _strict(out / "metrics.json")
    assert metrics["gps_uncovered_s"] > 40.0
    err = capsys.readouterr().err.strip().splitlines()
    assert err and all(ln.startswith("warning: ") for ln in err)
    assert any("the GPS covers" in ln and "_DGPS.log" in ln for ln in err)
    assert not list(out.glob(".*part*"))


@pytest.mark.parametrize(
    "args, code, says",
    [
        (["run", "{src}", "--out", "{file}"], 2, "exists and is not a directory"),
        (["run", "{src}", "--out", "{file}/below"], 2, "is not a directory"),
        (["run", "{tmp}/nowhere", "--out", "{tmp}/o"], 1, "nowhere: no such file or directory"),
        (
            ["run", "{tmp}/nowhere.bag", "--out", "{tmp}/o"],
            1,
            "nowhere.bag: no such file or directory",
        ),
        (["run", "{file}", "--out", "{tmp}/o"], 1, "not a directory, nor a named source"),
        (
            [
                "run",
                "{src}",
                "--backend",
                "ekf",
                "--out",
                "{tmp}/o",
                "--set",
                "extractor.min_votes=1.5",
            ],
            2,
            "whole number",
        ),
        (
            [
                "run",
                "{src}",
                "--backend",
                "ekf",
                "--out",
                "{tmp}/o",
                "--set",
                "extractor.rho_res_m=0",
            ],
            2,
            "rho_res_m",
        ),
        (
            [
                "run",
                "{src}",
                "--backend",
                "ekf",
                "--out",
                "{tmp}/o",
                "--set",
                "ekf.ahrs_period_s=nan",
            ],
            2,
            "finite number",
        ),
        (
            [
                "run",
                "{src}",
                "--backend",
                "ekf",
                "--out",
                "{tmp}/o",
                "--set",
                "ekf.ahrs_period_s=abc",
            ],
            2,
            "finite number",
        ),
        (
            ["sweep", "--seeds", "0", "--workers", "0", "--out", "{tmp}/o"],
            2,
            "--workers: must be >= 1",
        ),
        (["calibrate", "{src}", "--window", "nan"], 2, "--window"),
        (["calibrate", "{src}", "--window", "0"], 2, "must be > 0"),
        (["calibrate", "{src}", "--ahrs", "--line-noise"], 2, "one calibration at a time"),
        (["plot-scans", "{src}", "--out", "{tmp}"], 2, "must name a .png file"),
        (["plot-scans", "{src}", "--out", "{tmp}/pics"], 2, "must name a .png file"),
    ],
)
def test_command_line_misuse_is_one_line_with_its_exit_code(
    harbour, tmp_path, capsys, args, code, says
):
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    before = set(tmp_path.iterdir())
    filled = [a.format(src=harbour, file=a_file, tmp=tmp_path) for a in args]
    try:
        got = main(filled)
    except SystemExit as exc:  # argparse's usage errors
        got = int(exc.code or 0)
    err = capsys.readouterr().err.strip().splitlines()
    assert got == code and len(err) == 1 and says in err[0], (got, err)
    assert set(tmp_path.iterdir()) == before  # nothing created, nothing left


def test_an_isolated_dvl_spike_under_the_speed_gate_is_dropped_and_said(harbour, tmp_path):
    """A DVL row of 2.5 m/s (the log's cm/s) on a vehicle at ~0.5 m/s passes the 3 m/s speed gate: with the
    spike gate off ([gates] dvl_spike_sigmas = 0) it is taken silently and dead reckoning
    drifts; on (the default) it is taken as without bottom lock, counted and said with its
    time, and dead reckoning is the clean run's (ATE against the simulator's truth)."""
    base_ds = _open(harbour)[0]
    assert base_ds.report.counts["dvl_velocity_spikes"] == 0  # the simulator's noise passes
    base = run_backend(base_ds, "dr").metrics
    folder = _copy(harbour, tmp_path / "h")
    hit: list[float] = []

    def spike(t: float, f: list[str]) -> list[list[str]]:
        if t > 40.0 and not hit:
            hit.append(float(f[0]))
            return [[("250.0" if i == 12 else v) for i, v in enumerate(f)]]  # cm/s
        return [f]

    edit_log_rows(_log(folder, "DVL"), spike)
    off = tmp_path / "off.toml"
    off.write_text("[gates]\ndvl_spike_sigmas = 0.0\n")
    with warnings.catch_warnings(record=True):
        warnings.simplefilter("always")
        silent = open_dataset(folder, config_override=off)
    assert silent.report.counts["dvl_velocity_spikes"] == 0
    m_off = run_backend(silent, "dr").metrics
    ds, said = _open(folder)
    assert ds.report.counts["dvl_velocity_spikes"] == 1
    m_on = run_backend(ds, "dr").metrics
    assert m_on["fault_dvl_velocity_spikes"] == 1
    line = next(s for s in said if "off both neighbours" in s)
    assert "_DVL.log: 1 row(s)" in line and f"first at t={hit[0]:.3f} s" in line
    assert m_off["ate_mean_m"] > base["ate_mean_m"] + 0.3  # the silent wrong answer
    assert m_on["ate_mean_m"] == pytest.approx(base["ate_mean_m"], abs=0.05)


def test_two_dvl_spikes_in_a_row_are_found_and_a_real_change_of_velocity_is_not(harbour, tmp_path):
    """Two successive DVL rows of 2.5 m/s on a vehicle at ~0.5 m/s: each has the other as a
    close neighbour, so the isolated-spike test alone passes both and dead reckoning drifts in
    silence. As a pair (off the rows either side, which agree) both are taken as without lock
    and said, and dead reckoning is the clean run's; a step of the velocity, seen on seeded
    white noise, is not a pair."""
    base = run_backend(_open(harbour)[0], "dr").metrics
    folder = _copy(harbour, tmp_path / "h")
    hit: list[float] = []

    def spikes(t: float, f: list[str]) -> list[list[str]]:
        if t > 40.0 and len(hit) < 2:
            hit.append(float(f[0]))
            return [[("250.0" if i == 12 else v) for i, v in enumerate(f)]]  # cm/s
        return [f]

    edit_log_rows(_log(folder, "DVL"), spikes)
    ds, said = _open(folder)
    assert ds.report.counts["dvl_velocity_spikes"] == 2
    line = next(s for s in said if "off both neighbours" in s)
    assert "_DVL.log: 2 row(s)" in line and f"first at t={hit[0]:.3f} s" in line
    m = run_backend(ds, "dr").metrics
    assert m["ate_mean_m"] == pytest.approx(base["ate_mean_m"], abs=0.05)

    # the gate alone: white noise of 0.01 m/s at 5 Hz, a pair, then a step that stays
    rng = np.random.default_rng(7)
    n = 600
    t = np.arange(n) / 5.0
    v = np.column_stack([np.full(n, 0.5), np.zeros(n)]) + rng.normal(0.0, 0.01, (n, 2))
    v[200:202, 0] += 1.0
    v[400:, 0] += 0.6
    found, _, off = dvl_spikes(t, v, np.ones(n, dtype=bool), GateConfig(), 0.01)
    assert np.flatnonzero(found).tolist() == [200, 201]
    assert off[200] > 0.9 and off[201] > 0.9


def _dvl_times(folder: Path, factor: float) -> None:
    """The DVL log's velocity columns (water and bottom, cm/s) times ``factor``."""
    cols = (7, 8, 9, 11, 12, 13)
    edit_log_rows(
        _log(folder, "DVL"),
        lambda t, f: [[f"{float(v) * factor:.6g}" if i in cols else v for i, v in enumerate(f)]],
    )


def test_a_dvl_log_in_another_unit_is_said_with_the_likely_cause(harbour, tmp_path):
    """A marina-layout DVL log written in m/s (read as its cm/s) moves the vehicle 100 times
    too little; every run ended with a wrong answer and no warning (the marina so: ATE 29 m).
    Now opening it warns, naming the log, the speed with its unit and the columns' unit; the
    clean log does not. One in mm/s (10 times fast) is gated as too fast, said likewise."""
    clean, said_clean = _open(harbour)
    assert not [s for s in said_clean if "unit" in s]
    q_clean = run_backend(clean, "dr").metrics
    assert 0.3 < q_clean["dvl_speed_p50_mps"] < 0.6  # the simulated vehicle's 0.45 m/s
    slow = _copy(harbour, tmp_path / "mps")
    _dvl_times(slow, 0.01)
    ds, said = _open(slow)
    line = next(s for s in said if "implausibly slow" in s)
    assert str(_log(slow, "DVL")) in line and "bottomVelX/Y" in line and "cm/s" in line
    # the sigma check holds back: the scatter shrank with the unit, which the warning above says
    # (it blamed a right dvl_sigma_mps as 95 times the scatter); a bag's unit hint for a slow
    # DVL does not speak of a driver that reads fast
    from sonarslam.datasets.gates import _dvl_unit
    from sonarslam.slam.run.sources import warn_dvl_sigma

    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        assert warn_dvl_sigma(ds) == ""
    assert not record
    assert "fast" not in _dvl_unit(Path("run.bag"), slow=True)
    m = run_backend(ds, "dr").metrics
    assert m["dvl_speed_p50_mps"] == pytest.approx(q_clean["dvl_speed_p50_mps"] / 100, rel=1e-3)
    assert m["ate_truth_mean_m"] > 5.0 * q_clean["ate_truth_mean_m"]  # what the warning is for
    fast = _copy(harbour, tmp_path / "mmps")
    _dvl_times(fast, 10.0)
    line = next(s for s in _open(fast)[1] if "faster than 3 m/s" in s)
    assert "_DVL.log" in line and "unit is likely wrong" in line and "mm/s" in line


def test_a_dvl_sigma_far_above_the_dvls_scatter_is_said(harbour, tmp_path, capsys):
    """``[noise] dvl_sigma_mps = 2.0`` on a DVL whose scatter is 0.02 m/s was taken silently
    (a new user's review: the EKF's ATE 1.05 -> 2.04 m); now every run and ``info`` warn,
    naming the setting, the ratio and the scatter. The simulator's own sigma does not."""
    clean, _ = _open(harbour)
    with warnings.catch_warnings():
        warnings.simplefilter("error", DataWarning)
        run_backend(clean, "dr")  # the simulator's 0.02 m/s against its scatter: quiet
    told = tmp_path / "sigma.toml"
    told.write_text("[noise]\ndvl_sigma_mps = 2.0\n")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        wide = open_dataset(harbour, config_override=told)
    with pytest.warns(DataWarning) as record:
        run_backend(wide, "dr")
    (line,) = [str(w.message) for w in record if "dvl_sigma_mps" in str(w.message)]
    assert "[noise] dvl_sigma_mps = 2 m/s" in line and str(told) in line
    scatter = run_backend(clean, "dr").metrics["dvl_scatter_p50_mps"]
    assert 0.015 < scatter < 0.03  # the simulator's 0.02 m/s
    assert f"{2.0 / scatter:.0f} times the DVL's own scatter (median {scatter:.3g} m/s" in line
    assert main(["info", str(harbour), "--config", str(told)]) == 0
    out, err = capsys.readouterr()
    assert "[noise] dvl_sigma_mps = 2 m/s" in err and "dvl_sigma_mps too large?" in out


def test_exact_zeros_are_a_dropout_fill_only_while_the_vehicle_moves():
    """A hovering vehicle's DVL at a millimetre a second reads exact (0, 0) now and then: those
    rows are readings, kept (a review's still pool, rounded to 1 mm/s: one dropped and said as
    'never exact zeros'); a (0, 0) row amid a vehicle at 0.5 m/s is a dropout's fill, dropped."""
    from sonarslam.datasets.config import GateConfig
    from sonarslam.datasets.gates import SensorReport, gate_dvl
    from sonarslam.datasets.records import DvlSeries

    rng = np.random.default_rng(11)
    n = 400
    t = 1.7e9 + np.arange(n) / 5.0
    still = np.round(rng.normal(0.0, 0.002, (n, 2)), 3)
    assert np.sum(np.all(still == 0.0, axis=1)) >= 5  # exact zeros among the readings
    report = SensorReport()
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        gate_dvl(DvlSeries(t, still, np.ones(n, dtype=bool), np.zeros(n)), GateConfig(), report)
    assert report.counts["dvl_zero_velocity"] == 0
    assert not [w for w in said if "exactly (0, 0)" in str(w.message)]
    moving = np.column_stack([np.full(n, 0.5), np.zeros(n)]) + rng.normal(0.0, 0.01, (n, 2))
    moving[[100, 101, 250]] = 0.0
    report = SensorReport()
    with warnings.catch_warnings(record=True):
        warnings.simplefilter("always")
        out = gate_dvl(
            DvlSeries(t, moving, np.ones(n, dtype=bool), np.zeros(n)), GateConfig(), report
        )
    assert report.counts["dvl_zero_velocity"] == 3
    assert not out.valid[[100, 101, 250]].any()


def test_exact_zeros_of_a_rounded_velocity_are_readings(tmp_path):
    """A velocity logged to 0.1 m/s (QGroundControl's CSV export, ``resolution_mps``) reads
    (0, 0) whenever the vehicle is slower than 0.05 m/s per axis: readings, kept, also when
    every row is zero (a vehicle holding station) and beside rows of 0.1 m/s; a (0, 0) row
    amid 0.5 m/s is still a fill, and the message names the export, which has no lock flag
    (not the navigation CSV's dvl_valid column)."""
    from sonarslam.datasets.config import GateConfig
    from sonarslam.datasets.gates import SensorReport, gate_dvl
    from sonarslam.datasets.records import DvlSeries

    export = tmp_path / "2024-05-02 10-31-07 vehicle1.csv"
    export.write_text("Timestamp,heading,localPosition.vx,localPosition.vy\n", encoding="utf-8")
    rng = np.random.default_rng(12)
    n = 200
    t = 1.7e9 + np.arange(n, dtype=float)
    slow = np.round(rng.normal(0.03, 0.03, (n, 2)), 1)  # 0 and 0.1 m/s, mixed
    assert 20 < np.sum(np.all(slow == 0.0, axis=1)) < n - 20
    for v in (slow, np.zeros((n, 2))):
        report = SensorReport()
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always")
            out = gate_dvl(
                DvlSeries(t, v, np.ones(n, bool), np.zeros(n), export, 0.1), GateConfig(), report
            )
        assert report.counts["dvl_zero_velocity"] == 0 and out.valid.all()
        assert out.resolution_mps == 0.1
        assert not [w for w in said if "exactly (0, 0)" in str(w.message)]
    moving = np.round(np.column_stack([np.full(n, 0.5), np.zeros(n)]), 1)
    moving[[50, 120]] = 0.0
    report = SensorReport()
    with pytest.warns(DataWarning, match="exactly") as said:
        out = gate_dvl(
            DvlSeries(t, moving, np.ones(n, bool), np.zeros(n), export, 0.1), GateConfig(), report
        )
    assert report.counts["dvl_zero_velocity"] == 2 and not out.valid[[50, 120]].any()
    (line,) = [str(w.message) for w in said if "exactly" in str(w.message)]
    assert "dvl_valid" not in line and "QGroundControl's CSV export has no lock flag" in line
