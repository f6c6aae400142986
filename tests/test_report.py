"""slam.run.report: the tables hold the runs' own numbers (both spans, the truth on simulated
data), the published rows under the marina's table only, the ATE per segment; bands, figures."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

from sonarslam.datasets.simulator import simulate
from sonarslam.slam.cli.main import main
from sonarslam.slam.eval.ate import truth_errors
from sonarslam.slam.eval.consistency import nees_series
from sonarslam.slam.eval.evo_metrics import evo_ape
from sonarslam.slam.eval.published import PUBLISHED
from sonarslam.slam.eval.truth import truth_trajectory
from sonarslam.slam.io.maps import landmark_band_world
from sonarslam.slam.io.trajectory import cov_file, read_tum
from sonarslam.slam.run.report import report
from sonarslam.slam.run.report_data import load_run
from sonarslam.slam.run.run import run


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """dr and ekf on a short simulated harbour; the pipeline saves both runs' covariances, and
    the dr run's file is removed to check that the report copes with runs saved without it."""
    root = tmp_path_factory.mktemp("report")
    source = simulate("harbour", seed=5, out_dir=root / "h5", duration_s=150.0)
    dr = run(source, "dr", root / "h5-dr", progress=False)
    ekf = run(source, "ekf", root / "h5-ekf", progress=False)
    assert (ekf.out_dir / cov_file("ekf")).is_file()
    (dr.out_dir / cov_file("dr")).unlink()
    return {"dr": dr, "ekf": ekf, "source": source}


def _row(md: str, first: str, column: int = 1) -> list[str]:
    """The cells of the first table row whose cell ``column`` is ``first``."""
    for ln in md.splitlines():
        cells = [c.strip() for c in ln.strip().strip("|").split("|")]
        if ln.startswith("|") and len(cells) > column and cells[column] == first:
            return cells
    raise AssertionError(f"no row {first!r} in the report")


def test_band_of_a_landmark_is_the_95_percent_envelope():
    """rho-only covariance: the band is the segment shifted by +-sqrt(chi2_2(0.95)) sigma_rho
    along the normal; with a theta variance its half width at a point s along the line from the
    foot is sqrt(chi2 (s_rho^2 + s^2 s_theta^2)) to first order."""
    theta = 0.3
    n = np.array([np.cos(theta), np.sin(theta)])
    t = np.array([-n[1], n[0]])
    ends = np.stack([5.0 * n - 10.0 * t, 5.0 * n + 10.0 * t])
    lm = {"rho": 5.0, "theta": theta, "cov": [[0.04, 0.0], [0.0, 0.0]], "endpoints": ends.tolist()}
    seg, band = landmark_band_world(lm)
    np.testing.assert_array_equal(seg, ends)
    offsets = band @ n - 5.0
    k = np.sqrt(chi2.ppf(0.95, 2))
    np.testing.assert_allclose(np.abs(offsets), k * 0.2, atol=1e-9)
    lm["cov"] = [[0.04, 0.0], [0.0, 1e-6]]
    _, band = landmark_band_world(lm)
    s = band @ t
    half = np.abs(band @ n - 5.0)
    np.testing.assert_allclose(half, k * np.sqrt(0.04 + s**2 * 1e-6), rtol=1e-3)


def test_a_segment_is_drawn_over_what_its_bins_show():
    """A landmark whose extent runs 20 m past its bins into open water is drawn to where the
    bins within its 95 % half width stop; bins of another wall, off the line, do not count."""
    from sonarslam.slam.io.maps import landmark_layers, seen_extent

    lm = {"rho": 10.0, "theta": np.pi / 2, "cov": [[0.04, 0.0], [0.0, 1e-6]]}
    lm["endpoints"] = [[-30.0, 10.0], [30.0, 10.0]]  # the line y = 10 from x = -30 to 30
    rng = np.random.default_rng(4)
    x = rng.uniform(-30.0, 10.0, 400)
    wall = np.column_stack([x, 10.0 + rng.normal(0.0, 0.1, x.size)])
    other = np.column_stack([rng.uniform(10.0, 30.0, 200), np.full(200, 14.0)])  # 4 m off
    ends = seen_extent(lm, np.concatenate([wall, other]))
    assert ends[:, 1] == pytest.approx([10.0, 10.0], abs=1e-9)
    assert sorted(ends[:, 0]) == pytest.approx([-30.0, 10.0], abs=0.8)
    np.testing.assert_array_equal(seen_extent(lm, wall[:3]), lm["endpoints"])  # too few bins
    (segment,), (band,) = landmark_layers([lm], wall)
    np.testing.assert_allclose(segment, ends)
    assert band[:, 0].max() < 10.5  # the band follows the drawn segment


def test_report_table_holds_each_runs_numbers(runs, tmp_path):
    dr, ekf = runs["dr"], runs["ekf"]
    res = report([dr.out_dir, ekf.out_dir], tmp_path / "rep")
    md = res.path.read_text()
    for r, name in ((dr, "h5-dr"), (ekf, "h5-ekf")):
        cells = _row(md, name)
        m = r.metrics
        # simulated: against the truth (as it is, max, aligned), then GPS over both spans
        assert cells[2:7] == [
            f"{m['ate_truth_mean_m']:.2f}",
            f"{m['ate_truth_max_m']:.2f}",
            f"{m['ate_truth_aligned_mean_m']:.2f}",
            f"{m['ate_sonar_mean_m']:.2f}",
            f"{m['ate_mean_m']:.2f}",
        ]
        gps = read_tum(r.out_dir / "gps.tum")
        est = read_tum(r.out_dir / f"{r.backend}.tum")
        assert cells[8] == f"{evo_ape(gps, est).rmse_m:.2f}"
    # the NEES against the simulator's truth, the run's own figure (metrics.json's; the DR row
    # read 2.96 against its 2.978 when recomputed from the files), also without its covariance
    # file, whose absence only the figure needs
    nees = nees_series(ekf.trajectory, truth_trajectory(load_run(ekf.out_dir).dataset))
    assert _row(md, "h5-ekf")[9] == f"{nees.mean:.2f}" == f"{ekf.metrics['nees_pose_mean']:.2f}"
    assert _row(md, "h5-dr")[9] == f"{dr.metrics['nees_pose_mean']:.2f}"
    assert f"no {cov_file('dr')}" in md
    # no published figure under a simulated table
    assert "Mallios 2014, Table 2" not in md and "17.46" not in md
    assert re.search(r"\| EKF-SLAM\s*\|\s*1 \|\s*[0-9.]+ \|\s*0\.22 - 9\.35 \|", md)
    # the ATE per 300 s against the truth: the mean and max of the ATE's own errors
    t, e = truth_errors(ekf.trajectory, truth_trajectory(load_run(ekf.out_dir).dataset))
    first = (t - t[0]) < 300.0
    assert _row(md, "ekf", column=0)[1] == f"{e[first].mean():.2f} / {e[first].max():.2f}"
    # the EKF's constants beside the simulator's truth, the error in the run's own sigmas
    from sonarslam.slam.eval.truth import true_calibration

    ekf_run = load_run(ekf.out_dir)
    truth = true_calibration(ekf_run.dataset, ekf.trajectory.span_s[1])
    m = ekf.metrics
    assert truth["state_ahrs_bias_deg"] == pytest.approx(-2.0)  # the harbour's constant bias
    (line,) = [ln for ln in md.splitlines() if ln.startswith("- AHRS heading error (end): ")]
    z = (m["state_ahrs_bias_deg"] - truth["state_ahrs_bias_deg"]) / m["state_ahrs_bias_sd_deg"]
    # the value to the sd's resolution (two significant figures of the sd), never 4.99604e-14
    from sonarslam.slam.run.report_figures import _decimals, _fixed

    d = _decimals(m["state_ahrs_bias_sd_deg"])
    assert line == (
        f"- AHRS heading error (end): {_fixed(m['state_ahrs_bias_deg'], d)} ±"
        f" {_fixed(m['state_ahrs_bias_sd_deg'], d)} deg (1σ); truth"
        f" {_fixed(truth['state_ahrs_bias_deg'], d + 1)}, error {z:+.1f}σ"
    ), line
    assert "e-" not in line
    # each error band says which covariance model it is: different ones for dr and a closed loop
    from sonarslam.slam.run.report_figures import band_model

    assert "with its AHRS-bias state (sd" in band_model(
        load_run(ekf.out_dir, open_source=False), "EKF"
    )
    assert "no AHRS-bias state" in band_model(load_run(dr.out_dir, open_source=False), "dr")
    # where each run's figures come from: its version, commit and digests
    assert "## Provenance" in md
    for r, name in ((dr, "h5-dr"), (ekf, "h5-ekf")):
        prov = r.metrics["provenance"]
        cells = _row(md, f"{r.backend} (`{name}`)", column=0)
        assert cells[1] == prov["version"]
        assert prov["settings_sha256"][:16] in cells[3]
        assert prov["dataset_sha256"][:16] in cells[4]
        if prov["git_commit"] is not None:
            assert prov["git_commit"][:12] in cells[2]
    names = sorted(p.name for p in res.figures)
    assert names == [  # each run's own consistency.png (dr's written before its covariances went)
        "consistency_h5-dr.png",
        "consistency_h5-ekf.png",
        "errors_h5-dr.png",
        "errors_h5-ekf.png",
        "map_h5-ekf.png",
        "nees_h5-ekf.png",
        "segments_h5.png",
        "trajectories_h5.png",
    ]
    for p in res.figures:
        assert p.stat().st_size > 10_000 and f"({p.name})" in md


def test_published_rows_stand_under_the_marina_table_only(runs, tmp_path):
    """A run of a dataset named marina, reported without its dataset (as a real run): both
    spans side by side and the published rows under the sonar span; the simulated one beside it
    gets none."""
    marina = tmp_path / "marina-ekf"
    shutil.copytree(runs["ekf"].out_dir, marina)
    metrics = json.loads((marina / "metrics.json").read_text())
    metrics["source"] = str(tmp_path / "marina")
    (marina / "metrics.json").write_text(json.dumps(metrics))
    res = report([marina], tmp_path / "rep", open_sources=False)
    md = res.path.read_text()
    m = metrics
    cells = _row(md, "marina-ekf")
    assert cells[2:14] == [
        f"{m['ate_sonar_mean_m']:.2f}",
        f"{m['ate_sonar_sd_m']:.2f}",
        f"{m['ate_sonar_max_m']:.2f}",
        str(m["ate_sonar_n"]),
        f"{m['ate_sonar_aligned_mean_m']:.2f}",
        f"{m['ate_sonar_aligned_max_m']:.2f}",
        f"{m['ate_mean_m']:.2f}",
        f"{m['ate_sd_m']:.2f}",
        f"{m['ate_min_m']:.2f}",
        f"{m['ate_max_m']:.2f}",
        f"{m['ate_rmse_m']:.2f}",
        str(m["ate_n"]),
    ]
    for p in PUBLISHED:
        cells = _row(md, p["method"], column=0)
        assert cells[2:5] == [f"{p['mean']:.2f}", f"{p['sd']:.2f}", f"{p['max']:.2f}"]
        assert cells[6] == cells[8] == ""  # neither aligned nor under the whole run
    both = report([marina, runs["dr"].out_dir], tmp_path / "rep2", open_sources=False)
    text = both.path.read_text()
    marina_part, _, h5_part = text.partition("## h5")
    assert "Mallios 2014, Table 2" in marina_part and "Mallios 2014, Table 2" not in h5_part


def test_report_without_the_dataset_reuses_the_runs_map(runs, tmp_path, capsys):
    ekf = runs["ekf"]
    out = tmp_path / "rep2"
    assert main(["report", str(ekf.out_dir), "--out", str(out), "--no-source"]) == 0
    printed = capsys.readouterr().out
    assert f"whole run ATE mean {ekf.metrics['ate_mean_m']:.2f} m" in printed
    assert (out / "map_h5-ekf.png").read_bytes() == (ekf.out_dir / "map.png").read_bytes()
    assert not (out / "nees_h5-ekf.png").exists()  # no truth without the dataset


def test_two_sources_of_one_file_name_are_two_datasets(runs, tmp_path):
    """Two runs of bags named alike in two folders (``day1/run.bag``, ``day2/run.bag``) are
    two datasets: one section, one GPS and one trajectory figure each, named by the folder
    that tells them apart; grouped by the file name alone they shared one section in silence."""
    dirs = []
    for day in ("day1", "day2"):
        d = tmp_path / day
        shutil.copytree(runs["ekf"].out_dir, d)
        metrics = json.loads((d / "metrics.json").read_text())
        metrics["source"] = str(tmp_path / "bags" / day / "run.bag")
        (d / "metrics.json").write_text(json.dumps(metrics))
        dirs.append(d)
    res = report(dirs, tmp_path / "rep", open_sources=False)
    md = res.path.read_text()
    assert "## day1/run.bag" in md and "## day2/run.bag" in md, md
    assert {r["dataset"] for r in res.rows} == {"day1/run.bag", "day2/run.bag"}
    assert (tmp_path / "rep" / "trajectories_day1_run.bag.png").is_file()
    assert (tmp_path / "rep" / "trajectories_day2_run.bag.png").is_file()


def test_report_of_a_directory_that_is_no_run_is_one_line(tmp_path, capsys):
    assert main(["report", str(tmp_path), "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no metrics.json" in err[0]


def test_a_run_without_reference_draws_the_plane_alone(tmp_path: Path) -> None:
    """No GPS, no truth: no error panel (its time axis would be Unix seconds), only the plane."""
    import matplotlib.image

    from sonarslam.slam.io.plots import plot_trajectories
    from sonarslam.slam.io.trajectory import Trajectory

    t = 1.7e9 + np.linspace(0.0, 100.0, 51)
    poses = np.column_stack([np.linspace(0.0, 50.0, 51), np.zeros(51), np.zeros(51)])
    drawn = {"dr": Trajectory(t, poses), "isam2": Trajectory(t, poses + [0.0, 1.0, 0.0])}
    alone = plot_trajectories(tmp_path / "a.png", drawn, {}, "no reference", "no reference")
    errors = {"isam2": (t, np.full(t.size, 1.0))}
    both = plot_trajectories(tmp_path / "b.png", drawn, errors, "with errors", "GPS")
    h_a, w_a = matplotlib.image.imread(alone).shape[:2]
    h_b, w_b = matplotlib.image.imread(both).shape[:2]
    assert w_a / h_a < 0.75 * (w_b / h_b)  # one panel against two side by side


def test_the_report_gives_the_dvl_misalignment_and_its_correlation_with_the_sonar_yaw():
    """With the mounting and the misalignment both estimated, the report gave the mounting's
    yaw (near its prior) without the misalignment and their correlation, the part that
    explains it (metrics.json had both)."""
    from sonarslam.slam.io.trajectory import Trajectory
    from sonarslam.slam.run.report_data import RunData
    from sonarslam.slam.run.report_figures import calibration_lines

    tr = Trajectory(np.array([0.0, 1.0]), np.zeros((2, 3)))
    metrics = {
        "state_sonar_yaw_deg": 154.75,
        "state_sonar_yaw_sd_deg": 0.5,
        "state_misalignment_deg": 0.54,
        "state_misalignment_sd_deg": 0.69,
        "state_sonar_yaw_misalignment_corr": 0.7123,
    }
    lines = calibration_lines(RunData(Path("run"), metrics, tr, tr))
    assert "- DVL misalignment: 0.54 ± 0.69 deg (1σ)" in lines, lines
    assert any(
        ln.startswith("- correlation of the sonar mounting's yaw") and "+0.71" in ln for ln in lines
    )


def test_the_aligned_error_of_a_vehicle_that_never_moves_is_no_crash():
    """A pool world's true position never changes: the rigid alignment onto it is undetermined
    in rotation (evo's Umeyama raised 'Degenerate covariance rank' and the report crashed); the
    fit is then the translation of the centroids, the one rule of slam.eval.ate."""
    from sonarslam.slam.run.report_figures import _aligned_errors

    rng = np.random.default_rng(3)
    est = rng.normal(0.0, 0.1, (50, 2))
    ref = np.tile([4.0, -2.0], (50, 1))
    e = _aligned_errors(est, ref)
    assert e is not None
    np.testing.assert_allclose(e, est - est.mean(axis=0), atol=1e-12)
