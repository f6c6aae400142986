"""slam.run.report: the table holds the runs' own numbers and the published ones; bands and figures."""

from __future__ import annotations

import re

import numpy as np
import pytest
from scipy.stats import chi2

from datasets.simulator import simulate
from slam.cli.main import main
from slam.eval.consistency import nees_series
from slam.eval.evo_metrics import evo_ape, evo_rpe
from slam.eval.published import PUBLISHED
from slam.eval.truth import truth_trajectory
from slam.io.trajectory import COV_FILE, read_tum
from slam.run.report import landmark_band_world, load_run, report
from slam.run.run import run


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """dr and ekf on a short simulated harbour; the pipeline saves both runs' covariances, and
    the dr run's file is removed to check that the report copes with runs saved without it."""
    root = tmp_path_factory.mktemp("report")
    source = simulate("harbour", seed=5, out_dir=root / "h5", duration_s=150.0)
    dr = run(source, "dr", root / "h5-dr", progress=False)
    ekf = run(source, "ekf", root / "h5-ekf", progress=False)
    assert (ekf.out_dir / COV_FILE).is_file()
    (dr.out_dir / COV_FILE).unlink()
    return {"dr": dr, "ekf": ekf, "source": source}


def _row(md: str, run_name: str) -> list[str]:
    line = next(ln for ln in md.splitlines() if f"| {run_name} |" in ln)
    return [c.strip() for c in line.strip("|").split("|")]


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


def test_report_table_holds_each_runs_numbers(runs, tmp_path):
    dr, ekf = runs["dr"], runs["ekf"]
    res = report([dr.out_dir, ekf.out_dir], tmp_path / "rep")
    md = res.path.read_text()
    for r, name in ((dr, "h5-dr"), (ekf, "h5-ekf")):
        cells = _row(md, name)
        m = r.metrics
        assert cells[3:9] == [
            f"{m['ate_mean_m']:.2f}",
            f"{m['ate_sd_m']:.2f}",
            f"{m['ate_min_m']:.2f}",
            f"{m['ate_max_m']:.2f}",
            f"{m['ate_rmse_m']:.2f}",
            str(m["ate_n"]),
        ]
        gt = read_tum(r.out_dir / "ground_truth.tum")
        est = read_tum(r.out_dir / "trajectory.tum")
        assert cells[10] == f"{evo_ape(gt, est).rmse_m:.2f}"
        assert cells[12] == f"{evo_rpe(gt, est, delta_m=10.0).rmse_m:.2f}"
    # NEES only where the covariances were saved; it is the NEES against the simulator's truth
    nees = nees_series(ekf.trajectory, truth_trajectory(load_run(ekf.out_dir).dataset))
    assert _row(md, "h5-ekf")[14] == f"{nees.mean:.2f}"
    assert _row(md, "h5-dr")[14] == ""
    assert f"no {COV_FILE}" in md
    for p in PUBLISHED:
        assert f"| {p['mean']:.2f} | {p['sd']:.2f} | {p['min']:.2f} | {p['max']:.2f} |" in md
    assert "| 17.46 | 11.47 | 0.09 | 45.42 |" in md
    assert re.search(r"\| EKF-SLAM \| 1 \| [0-9.]+ \| 0\.22 - 9\.35 \|", md)
    names = sorted(p.name for p in res.figures)
    assert names == [
        "errors_h5-dr.png",
        "errors_h5-ekf.png",
        "map_h5-ekf.png",
        "nees_h5-ekf.png",
        "trajectories_h5.png",
    ]
    for p in res.figures:
        assert p.stat().st_size > 10_000 and f"({p.name})" in md


def test_report_without_the_dataset_reuses_the_runs_map(runs, tmp_path, capsys):
    ekf = runs["ekf"]
    out = tmp_path / "rep2"
    assert main(["report", str(ekf.out_dir), "--out", str(out), "--no-source"]) == 0
    printed = capsys.readouterr().out
    assert f"ATE mean {ekf.metrics['ate_mean_m']:.2f} m" in printed
    assert (out / "map_h5-ekf.png").read_bytes() == (ekf.out_dir / "map.png").read_bytes()
    assert not (out / "nees_h5-ekf.png").exists()  # no truth without the dataset


def test_report_of_a_directory_that_is_no_run_is_one_line(tmp_path, capsys):
    assert main(["report", str(tmp_path), "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no metrics.json" in err[0]
