"""A Ping360 ``.bin`` with its navigation in a CSV written as a new user writes one (docs/data.md):
each slip that ran on to a wrong answer is refused, or said, naming the file (review 38)."""

from __future__ import annotations

import csv
import json
import math
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from sonarslam.datasets.dataset import Dataset
from sonarslam.datasets.errors import DataError, DataWarning
from sonarslam.datasets.gates import MAX_BEAMS_OUTSIDE_NAV
from sonarslam.datasets.ping360 import (
    Ping360Settings,
    read_nav_csv,
    read_ping360_log,
    write_ping360_log,
)
from sonarslam.datasets.simulator.ping360 import write_ping360_run
from sonarslam.datasets.source import open_dataset
from sonarslam.slam.cli.main import main
from sonarslam.slam.run.sources import dead_reckoning_trajectory

COLUMNS = ["t_s", "dvl_vx_mps", "dvl_vy_mps", "dvl_valid", "ahrs_yaw_enu_rad",
           "ahrs_yaw_rate_rad_per_s"]  # fmt: skip


@pytest.fixture(scope="module")
def layout(ping360_layout: Path) -> Path:
    """The harbour dive in the marina layout (conftest's ``ping360_layout``, read only)."""
    return ping360_layout


def _quiet_open(path: Path, **kw: object) -> Dataset:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        return open_dataset(path, **kw)  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def direct(layout: Path) -> Dataset:
    return _quiet_open(layout)


@pytest.fixture(scope="module")
def binlog(direct: Dataset, layout: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_ping360_run(direct, tmp_path_factory.mktemp("navcsv") / "bin", layout)


def _write_nav(
    d: Dataset,
    path: Path,
    columns: list[str] = COLUMNS,
    yaw: Callable[[float], float] = lambda y: y,
    time: Callable[[float], float] = lambda t: t,
    keep: Callable[[float], bool] = lambda t: True,
) -> Path:
    """``d``'s DVL and AHRS as a navigation CSV as docs/data.md writes it, with a user's slip:
    a column left out, the yaw or the times converted wrongly, rows cut."""
    rows = [
        (t, {"dvl_vx_mps": v[0], "dvl_vy_mps": v[1], "dvl_valid": int(ok)})
        for t, v, ok in zip(d.dvl.t, d.dvl.v_mps, d.dvl.valid, strict=True)
    ]
    rows += [
        (t, {"ahrs_yaw_enu_rad": yaw(y), "ahrs_yaw_rate_rad_per_s": r})
        for t, y, r in zip(
            d.attitude.t, d.attitude.yaw_rad, d.attitude.yaw_rate_rad_per_s, strict=True
        )
    ]
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(columns)
        for t, cells in sorted(rows, key=lambda r: r[0]):
            if keep(t):
                w.writerow(
                    [repr(float(time(t)))]
                    + [repr(float(cells[c])) if c in cells else "" for c in columns[1:]]
                )
    return path


def _messages(caught: list[warnings.WarningMessage]) -> str:
    return "\n".join(str(w.message) for w in caught if issubclass(w.category, DataWarning))


def test_dvl_dropouts_written_as_zeros_without_dvl_valid_are_taken_as_no_lock(
    binlog: Path, direct: Dataset, tmp_path: Path
) -> None:
    """docs/data.md: ``dvl_valid`` is optional (default 1); a CSV without it carries the DVL's
    dropouts as (0, 0), which a locked DVL never reads (its noise): those rows are taken as
    without lock, said once, and the navigation is the one the lock flags give."""
    lost = ~direct.dvl.valid
    assert lost.sum() >= 5 and np.all(direct.dvl.v_mps[lost] == 0.0)  # the dropouts to find
    assert not np.any(np.all(direct.dvl.v_mps[~lost] == 0.0, axis=1))  # a locked DVL's noise
    nav = _write_nav(direct, tmp_path / "nav.csv", [c for c in COLUMNS if c != "dvl_valid"])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        d = open_dataset(binlog, nav=nav)
    said = _messages(caught)
    assert f"{nav}: {int(lost.sum())} of the {direct.dvl.t.size} locked row(s) read exactly" in said
    assert "dvl_valid column" in said
    np.testing.assert_array_equal(d.dvl.valid, direct.dvl.valid)
    assert d.report.counts["dvl_zero_velocity"] == int(lost.sum())
    assert d.report.gaps["dvl"].count == direct.report.gaps["dvl"].count >= 1  # the gap is seen
    # the dead reckoning is the lock flags' (the dropouts held, not a stop)
    flagged = _quiet_open(binlog, nav=_write_nav(direct, tmp_path / "flagged.csv"))
    a, b = dead_reckoning_trajectory(d), dead_reckoning_trajectory(flagged)
    np.testing.assert_allclose(a.poses_wTb, b.poses_wTb, rtol=0, atol=1e-9)


def test_a_yaw_in_degrees_is_refused_naming_the_line(
    direct: Dataset, binlog: Path, tmp_path: Path
) -> None:
    nav = _write_nav(direct, tmp_path / "deg.csv", yaw=math.degrees)
    with pytest.raises(DataError, match=r"deg.csv:\d+: ahrs_yaw_enu_rad = .* degrees\?"):
        read_nav_csv(nav)
    # the line named holds the first AHRS yaw beyond 2 pi
    with pytest.raises(DataError) as err:
        read_nav_csv(nav)
    line = int(str(err.value).split(f"{nav}:")[1].split(":")[0])
    row = nav.read_text().splitlines()[line - 1].split(",")
    assert abs(float(row[COLUMNS.index("ahrs_yaw_enu_rad")])) > 2 * math.pi
    # radians are read, in any branch: [0, 2 pi) as well as (-pi, pi]
    nav = _write_nav(direct, tmp_path / "rad.csv", yaw=lambda y: y % (2 * math.pi))
    _, att, _ = read_nav_csv(nav)
    np.testing.assert_allclose(
        np.angle(np.exp(1j * (att.yaw_rad - direct.attitude.yaw_rad))), 0.0, rtol=0, atol=1e-12
    )


def test_an_ned_heading_beside_an_enu_gyro_is_refused(direct: Dataset, tmp_path: Path) -> None:
    """As the bag reader refuses it (one check, datasets/gates.py check_heading_sense)."""
    assert np.ptp(np.unwrap(direct.attitude.yaw_rad)) > math.radians(90.0)  # the run turns
    nav = _write_nav(direct, tmp_path / "ned.csv", yaw=lambda y: math.pi / 2 - y)
    with pytest.raises(
        DataError,
        match=r"ned.csv: ahrs_yaw_enu_rad turns against ahrs_yaw_rate_rad_per_s \(correlation"
        r" -[01]\.\d\d over the run\): the heading is not ENU",
    ):
        read_nav_csv(nav)
    # both in NED (the rate derived from the heading): no contradiction to see
    no_rate = [c for c in COLUMNS if c != "ahrs_yaw_rate_rad_per_s"]
    read_nav_csv(_write_nav(direct, tmp_path / "ned2.csv", no_rate, yaw=lambda y: math.pi / 2 - y))


@pytest.mark.parametrize(
    ("time", "likely"),
    [
        (lambda t: t * 1000.0, r"milliseconds\? \(x1000 the beams' times\)"),
        (lambda t: t - 1_700_000_000.0, r"relative to the start\?"),
    ],
)
def test_nav_times_not_in_unix_seconds_are_named_as_such(
    direct: Dataset,
    binlog: Path,
    tmp_path: Path,
    time: Callable[[float], float],
    likely: str,
) -> None:
    nav = _write_nav(direct, tmp_path / "t.csv", time=time)
    with pytest.raises(DataError, match=r"t.csv: .* not a time zone .* t_s column is not Unix"
                       r" seconds on the sonar's clock: " + likely) as err:  # fmt: skip
        _quiet_open(binlog, nav=nav)
    assert "utc_offset_h" not in str(err.value)


def test_a_nav_csv_covering_part_of_the_log_is_said_and_counted(
    direct: Dataset, binlog: Path, tmp_path: Path
) -> None:
    t0, t1 = direct.nav_span_s
    half = 0.5 * (t0 + t1)
    nav = _write_nav(direct, tmp_path / "half.csv", keep=lambda t: t <= half)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        d = open_dataset(binlog, nav=nav)
    outside = len(d.beams) - len(d.nav_beams())
    assert outside > 0.4 * len(d.beams)
    said = _messages(caught)
    assert (
        f"{outside} of the {len(d.beams)} sonar beams" in said and "outside the navigation" in said
    )
    assert d.report.beams_outside_nav == outside
    out = tmp_path / "run"
    assert main(["run", str(binlog), "--nav", str(nav), "--backend", "dr", "--out", str(out),
                 "--quiet"]) == 0  # fmt: skip
    assert json.loads((out / "metrics.json").read_text())["beams_outside_nav"] == outside
    # the whole navigation: a few beams at the ends, under the share warned of
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        whole = open_dataset(binlog, nav=_write_nav(direct, tmp_path / "all.csv"))
    assert whole.report.beams_outside_nav <= MAX_BEAMS_OUTSIDE_NAV * len(whole.beams)
    assert "outside the navigation" not in _messages(caught)


def test_a_gain_change_in_the_log_is_said(
    binlog: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = read_ping360_log(binlog, Ping360Settings())
    b = log.beams
    stamps = np.round((b.t_s - log.start_ms / 1000.0) * 1000).astype(np.int64)
    grads = np.round(b.transducer_angle_rad * 200 / np.pi).astype(np.int64) % 400
    half = len(b) // 2
    gains = np.where(np.arange(len(b)) < half, 1, 0)
    path = tmp_path / binlog.name
    write_ping360_log(path, stamps, grads, b.intensities, log.sample_period_ticks,
                      gain_settings=gains)  # fmt: skip
    with pytest.warns(DataWarning) as caught:
        changed = read_ping360_log(path, Ping360Settings())
    said = _messages(list(caught))
    assert (
        f"gain_setting changed 1 time(s) during the log, the first at t={b.t_s[half]:.3f} s" in said
    )
    assert "1 (normal) -> 0 (low)" in said
    assert changed.counts["ping360_gain_changes"] == 1
    np.testing.assert_array_equal(changed.beams.intensities, b.intensities)
    assert log.counts["ping360_gain_changes"] == 0
    capsys.readouterr()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        assert main(["info", str(path), "--nav", str(binlog.parent / "nav.bag")]) == 0
    assert "gain_setting changed 1 time(s)" in capsys.readouterr().out
