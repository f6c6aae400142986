"""``sonarslam extract`` and :mod:`sonarslam.slam.run.extraction`: presets, TOML over a preset, the 95 % band
of a segment, and an end-to-end run on a simulated harbour checked against its true walls."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

from sonarslam.datasets.simulator import simulate
from sonarslam.datasets.source import open_dataset
from sonarslam.features.config import ExtractorConfig
from sonarslam.features.geometry import inverse, line_frame_to_world, transform_points
from sonarslam.features.line import LineFeature
from sonarslam.slam.cli.main import main
from sonarslam.slam.eval.lines import GATE_RAD, HARBOUR_GATE_M, match_features
from sonarslam.slam.io.maps import segment_band_world
from sonarslam.slam.run.presets import EXTRACTOR_PRESETS, extractor_config, preset_for
from sonarslam.sonar.beam import SonarBeam

# -- configuration ---------------------------------------------------------------------------


def test_the_preset_follows_the_beams() -> None:
    raw = [SonarBeam(t=0.0, transducer_angle_rad=0.0, intensities=np.zeros(10, np.uint8))]
    mask = [
        SonarBeam(
            t=0.0, transducer_angle_rad=0.0, intensities=np.zeros(10, np.uint8), thresholded=True
        )
    ]
    assert preset_for(raw) == "default"
    assert preset_for(mask) == "marina"


def test_toml_fields_replace_the_preset_s(tmp_path: Path) -> None:
    path = tmp_path / "extractor.toml"
    path.write_text('[extractor]\nmin_votes = 12\ncovariance_method = "seed"\n')
    marina = EXTRACTOR_PRESETS["marina"]
    cfg = extractor_config("marina", path)
    assert (cfg.min_votes, cfg.covariance_method) == (12, "seed")
    assert cfg.replace(min_votes=marina.min_votes, covariance_method="fit") == marina
    over = extractor_config("marina", path, {"min_votes": 20, "max_range_m": 25.0})
    assert (over.min_votes, over.max_range_m, over.covariance_method) == (20, 25.0, "seed")
    assert extractor_config("default") == ExtractorConfig()
    path.write_text("min_vote = 12\n")
    with pytest.raises(ValueError, match="min_vote"):
        extractor_config("default", path)
    with pytest.raises(ValueError, match="preset"):
        extractor_config("no-such-preset")


# -- the 95 % band -----------------------------------------------------------------------------


def _feature(cov: np.ndarray) -> LineFeature:
    wTr = np.array([3.0, -2.0, 0.7])
    rho, theta = 8.0, 0.4
    n, t = np.array([np.cos(theta), np.sin(theta)]), np.array([-np.sin(theta), np.cos(theta)])
    ends_r = np.stack([rho * n - 6.0 * t, rho * n + 4.0 * t])
    return LineFeature(0.0, wTr, rho, theta, cov, 30, ends_r, 30)


def _offsets(feature: LineFeature, band_w: np.ndarray, rho: np.ndarray, theta: np.ndarray):
    """Signed offsets, along the nominal normal, of lines (rho, theta) at the band's stations;
    and the band's own two sides there."""
    band_r = transform_points(inverse(feature.wTr), band_w)
    n = np.array([np.cos(feature.theta_rad), np.sin(feature.theta_rad)])
    a = band_r.shape[0] // 2
    side_a, side_b = band_r[:a], band_r[a:][::-1]
    q = 0.5 * (side_a + side_b) - (0.5 * (side_a + side_b) @ n - feature.rho_m)[:, None] * n
    nk = np.stack([np.cos(theta), np.sin(theta)], axis=-1)
    lam = (rho[None, :] - q @ nk.T) / (nk @ n)[None, :]
    return lam, side_a @ n - feature.rho_m, side_b @ n - feature.rho_m


def test_band_is_the_envelope_of_the_lines_in_the_95_percent_ellipse() -> None:
    cov = np.array([[0.02**2, -0.3 * 0.02 * 0.01], [-0.3 * 0.02 * 0.01, 0.01**2]])
    ft = _feature(cov)
    band = segment_band_world(ft, n_along=21)  # 72 points on the ellipse
    z0 = np.array([ft.rho_m, ft.theta_rad])
    root = np.linalg.cholesky(cov) * np.sqrt(chi2.ppf(0.95, 2))
    rng = np.random.default_rng(7)
    # lines drawn uniformly inside the ellipse stay in the band (up to 1 % of its half width,
    # the chord error of 72 boundary points)
    phi = rng.uniform(0.0, 2.0 * np.pi, 5000)
    u = np.sqrt(rng.uniform(0.0, 1.0, 5000)) * np.stack([np.cos(phi), np.sin(phi)])
    z = z0[:, None] + root @ u
    lam, hi, lo = _offsets(ft, band, z[0], z[1])
    half = 0.5 * (hi - lo)
    assert np.all(lam.max(axis=1) <= hi + 0.01 * half)
    assert np.all(lam.min(axis=1) >= lo - 0.01 * half)
    # and it is tight: lines on a dense boundary reach its sides
    phi = np.linspace(0.0, 2.0 * np.pi, 3600, endpoint=False)
    z = z0[:, None] + root @ np.stack([np.cos(phi), np.sin(phi)])
    lam, _, _ = _offsets(ft, band, z[0], z[1])
    np.testing.assert_allclose(lam.max(axis=1), hi, atol=0.01 * half.min())
    np.testing.assert_allclose(lam.min(axis=1), lo, atol=0.01 * half.min())
    # to first order the half width at s along the line is sqrt(chi2 [1, -s] cov [1, -s]^T)
    t = np.array([-np.sin(ft.theta_rad), np.cos(ft.theta_rad)])
    s = np.linspace(ft.endpoints_r[0] @ t, ft.endpoints_r[1] @ t, 21)
    lin = np.sqrt(chi2.ppf(0.95, 2) * (cov[0, 0] - 2 * s * cov[0, 1] + s**2 * cov[1, 1]))
    np.testing.assert_allclose(half, lin, rtol=0.01)


def test_band_of_a_certain_line_is_its_segment_in_the_world() -> None:
    ft = _feature(np.diag([1e-16, 1e-16]))
    band = segment_band_world(ft, n_along=5)
    ends_w = ft.endpoints_world()
    np.testing.assert_allclose(band[0], ends_w[0], atol=1e-6)
    np.testing.assert_allclose(band[4], ends_w[1], atol=1e-6)
    line_w = line_frame_to_world(ft.z, ft.wTr)[0]
    n_w = np.array([np.cos(line_w[1]), np.sin(line_w[1])])
    np.testing.assert_allclose(band @ n_w, line_w[0], atol=1e-6)


# -- end to end ------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def harbour_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("extract")
    data = simulate("harbour", seed=2, out_dir=root / "h2", duration_s=200.0)
    out = root / "out"
    assert main(["extract", str(data), "--poses", "truth", "--out", str(out), "--quiet"]) == 0
    return Path(data), out


def _read_lines(path: Path) -> list[LineFeature]:
    feats = []
    for row in path.read_text().splitlines():
        o = json.loads(row)
        wTr = np.array([o["x"], o["y"], o["yaw"]])
        ends_r = transform_points(inverse(wTr), np.array(o["endpoints"]))
        cov = np.array(o["cov"])
        feats.append(LineFeature(o["t"], wTr, o["rho"], o["theta"], cov, o["votes"], ends_r, o["n_voters"]))  # fmt: skip
    return feats


def test_extract_finds_the_true_walls_of_a_simulated_harbour(harbour_run) -> None:
    data, out = harbour_run
    stats = json.loads((out / "extract.json").read_text())
    truth = json.loads((data / "truth.json").read_text())
    feats = _read_lines(out / "lines.jsonl")
    assert stats["preset"] == "default" and stats["poses"] == "truth"
    assert stats["features"] == len(feats) >= 10
    assert stats["beams"] + stats["beams_outside_pose_span"] == len(open_dataset(data).nav_beams())
    assert stats["beam_time_p50_us"] <= stats["beam_time_p99_us"]
    assert stats["realtime_factor"] == pytest.approx(stats["data_s"] / stats["wall_s"], rel=1e-9)
    # the readers' frame is the world minus the first GPS fix
    walls = np.asarray(truth["walls_m"]) - np.asarray(truth["first_fix_enu_m"])
    matches = match_features(feats, walls, HARBOUR_GATE_M, GATE_RAD)
    assert all(m.matched for m in matches)
    errors = np.array([m.error for m in matches])
    assert np.median(np.abs(errors[:, 0])) < 0.05  # m, with 0.1 m bins
    assert np.median(np.abs(errors[:, 1])) < np.deg2rad(0.5)
    for ft in feats:
        np.testing.assert_allclose(ft.cov, ft.cov.T, atol=1e-15)
        assert np.all(np.linalg.eigvalsh(ft.cov) > 0.0)
        n = np.array([np.cos(ft.theta_rad), np.sin(ft.theta_rad)])
        np.testing.assert_allclose(ft.endpoints_r @ n, ft.rho_m, atol=1e-6)
    png = (out / "lines_world.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"


def test_extract_reports_a_bad_source_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["extract", str(tmp_path / "nowhere"), "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("sonarslam extract: error:")
