"""slam.run.sweep: parsing, task expansion, overrides, and sweeps whose rows equal direct runs."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

import sonarslam.slam.run.sweep as sweep_mod
from sonarslam.datasets.simulator import make_scenario, simulate_records, write_dataset
from sonarslam.datasets.source import open_dataset
from sonarslam.slam.backends.ekf import EkfConfig
from sonarslam.slam.cli.main import main
from sonarslam.slam.eval.ate import ate_against_gps, ate_against_truth
from sonarslam.slam.eval.consistency import anees, nees_on_grid, nees_series
from sonarslam.slam.eval.truth import truth_trajectory
from sonarslam.slam.run.presets import apply_overrides, parse_value
from sonarslam.slam.run.run import run, run_backend
from sonarslam.slam.run.sources import dead_reckoning_trajectory
from sonarslam.slam.run.sweep import (
    expand_tasks,
    load_grid_toml,
    pair_with_baseline,
    parse_grid,
    parse_seeds,
    simulate_cached,
    summarise,
    sweep,
)
from sonarslam.slam.run.sweep_summary import held_back_note

DURATION_S = 90.0


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    """Two short harbours, simulated once for the module (as a sweep caches them)."""
    root = tmp_path_factory.mktemp("simcache")
    for seed in (0, 1):
        simulate_cached("harbour", seed, DURATION_S, root)
    return root


def test_seeds_parse_ranges_and_lists():
    assert parse_seeds("0-49") == list(range(50))
    assert parse_seeds("0,2,5-7,2") == [0, 2, 5, 6, 7]
    assert parse_seeds("3") == [3]
    for bad in ("a", "5-2", "1-", ""):
        with pytest.raises(ValueError, match="--seeds"):
            parse_seeds(bad)


def test_grid_values_are_typed():
    assert [parse_value(v) for v in ("10", "0.5", "true", "None", "jcbb")] == [
        10,
        0.5,
        True,
        None,
        "jcbb",
    ]
    grid = parse_grid(["ekf.association=jcbb,nn", "extractor.min_votes=10,15"])
    assert grid == {"ekf.association": ["jcbb", "nn"], "extractor.min_votes": [10, 15]}
    with pytest.raises(ValueError, match="SCOPE.FIELD"):
        parse_grid(["min_votes=10"])


def test_grid_toml_flat_and_nested(tmp_path):
    f = tmp_path / "g.toml"
    f.write_text(
        '[grid]\n"ekf.association" = ["jcbb", "nn"]\n[grid.extractor]\nmin_votes = [10, 15]\n'
    )
    assert load_grid_toml(f) == {"ekf.association": ["jcbb", "nn"], "extractor.min_votes": [10, 15]}


def test_tasks_take_only_the_axes_of_their_back_end():
    grid = {"ekf.association": ["jcbb", "nn"], "extractor.min_votes": [10, 15]}
    tasks = expand_tasks([0, 1], ["dr", "ekf"], grid)
    assert len(tasks) == 2 * (1 + 4)
    assert [t.params for t in tasks if t.backend == "dr"] == [(), ()]
    ekf0 = [t.params_dict for t in tasks if t.backend == "ekf" and t.seed == 0]
    assert {(p["ekf.association"], p["extractor.min_votes"]) for p in ekf0} == {
        ("jcbb", 10),
        ("jcbb", 15),
        ("nn", 10),
        ("nn", 15),
    }
    with pytest.raises(ValueError, match="no back end"):
        expand_tasks([0], ["dr"], {"ekf.association": ["nn"]})
    with pytest.raises(ValueError, match="no settings"):
        expand_tasks([0], ["dr"], {"dr.anything": [1]})
    with pytest.raises(ValueError, match="unknown 'kalman'"):
        expand_tasks([0], ["kalman"], {})


def test_overrides_reach_nested_fields_and_name_the_valid_ones():
    cfg = apply_overrides(EkfConfig(), {"association": "nn", "noise.ahrs_bias_sigma_deg": 3.0})
    assert cfg.association.method == "nn" and cfg.noise.ahrs_bias_sigma_deg == 3.0
    cfg = apply_overrides(EkfConfig(), {"association.gate_probability": 0.95})
    assert cfg.association.gate_probability == 0.95 and cfg.association.method == "jcbb"
    with pytest.raises(ValueError, match="association.gate: unknown field.*gate_probability"):
        apply_overrides(EkfConfig(), {"association.gate": 0.9})
    with pytest.raises(
        ValueError, match="^association.method: must be one of .jcbb., .nn., got .icp.$"
    ):
        apply_overrides(EkfConfig(), {"association": "icp"})


def test_simulation_is_cached_per_seed(cache):
    folder = simulate_cached("harbour", 0, DURATION_S, cache)
    assert folder == str(cache / "harbour_0_90s")
    assert sorted(p.name for p in cache.iterdir()) == ["harbour_0_90s", "harbour_1_90s"]


def test_one_runner_for_the_cli_and_the_sweep(cache, tmp_path):
    """``sonarslam run`` and the sweep's tasks run through the same runner: the metrics written
    by run() are run_backend()'s to the last bit, settings of another back end are refused."""
    source = cache / "harbour_1_90s"
    dataset = open_dataset(source)
    piped = run(source, "ekf", tmp_path / "ekf", progress=False).metrics
    mine = run_backend(dataset, "ekf").metrics
    for key in ("ate_mean_m", "ate_rmse_m", "ate_max_m", "ate_n", "line_features"):
        assert mine[key] == piped[key]
    assert mine["assoc_observations"] == piped["assoc_observations"]
    assert mine["extractor_preset"] == "default"
    with pytest.raises(ValueError, match="does not apply"):
        run_backend(dataset, "ekf", {"isam2.robust": "cauchy"})
    with pytest.raises(ValueError, match="no settings"):
        run_backend(dataset, "dr", {"ekf.association": "nn"})


def test_extractor_override_reaches_the_front_end(cache):
    dataset = open_dataset(cache / "harbour_0_90s")
    run_ = run_backend(dataset, "ekf", {"extractor.min_votes": 10**6})
    assert run_.metrics["line_features"] == 0
    assert run_.metrics["landmarks"] == 0
    assert run_.metrics["assoc_observations"] == 0
    assert run_.metrics["beams"] > 1000


def test_sweep_on_a_local_cluster_gives_the_rows_of_direct_runs(cache, tmp_path, capsys):
    """2 seeds x (dr, ekf with two association methods) on a LocalCluster (through the CLI):
    each dr row is the dead-reckoning ATE of its seed, each ekf row the one of run_backend, and
    the summary's ANEES is that of nees.npz. One worker process (--workers 1; the default is 2):
    the tasks still cross a process boundary both ways, and each worker process costs ~9 s of
    CPU to start (spawn, then distributed's and the library's imports)."""
    out = tmp_path / "sweep"
    argv = ["sweep", "--world", "harbour", "--seeds", "0-1", "--backend", "dr,ekf"]
    argv += ["--duration", str(DURATION_S), "--grid", "ekf.association=jcbb,nn", "--workers", "1"]
    argv += ["--out", str(out), "--cache", str(cache)]
    assert main(argv + ["--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "6 runs (0 failed)" in printed
    table = pd.read_csv(out / "sweep.csv")
    assert len(table) == 6 and table["error"].isna().all()
    assert list(table.columns[:3]) == ["seed", "backend", "ekf.association"]
    for seed in (0, 1):
        dataset = open_dataset(cache / f"harbour_{seed}_90s")
        dr = table[(table.seed == seed) & (table.backend == "dr")].iloc[0]
        expected = ate_against_gps(dead_reckoning_trajectory(dataset), dataset.gps)
        assert dr["ate_mean_m"] == pytest.approx(expected.ate_mean_m, rel=1e-12)
        for method in ("jcbb", "nn"):
            row = table[(table.seed == seed) & (table["ekf.association"] == method)].iloc[0]
            direct = run_backend(dataset, "ekf", {"ekf.association": method}).metrics
            assert row["ate_mean_m"] == pytest.approx(direct["ate_mean_m"], rel=1e-12)
            assert row["assoc_associated"] == direct["assoc_associated"]
    nees = np.load(out / "nees.npz")
    assert nees["pose"].shape == (6, nees["t_rel_s"].size)
    summary = pd.read_csv(out / "summary.csv")
    assert list(summary["runs"]) == [2, 2, 2]
    for k, label in enumerate(summary["config"]):
        rows = [i for i in range(6) if sweep_mod.config_labels(table)[i] == label]
        assert summary.loc[k, "anees"] == pytest.approx(anees(nees["pose"][rows], 3).mean, rel=1e-9)
        assert summary.loc[k, "anees_band_lo"] == pytest.approx(0.6187, abs=1e-4)  # chi2(6)/2
    for name in ("sweep.png", "anees.png"):
        assert (out / name).stat().st_size > 10_000


def test_synchronous_sweep_equals_the_cluster_one(cache, tmp_path):
    res = sweep(
        [0],
        ["dr"],
        tmp_path / "s",
        world="harbour",
        duration_s=DURATION_S,
        cache_dir=cache,
        scheduler="synchronous",
        progress=False,
    )
    dataset = open_dataset(cache / "harbour_0_90s")
    expected = ate_against_gps(dead_reckoning_trajectory(dataset), dataset.gps)
    assert res.table.loc[0, "ate_mean_m"] == pytest.approx(expected.ate_mean_m, rel=1e-12)
    dr = dead_reckoning_trajectory(dataset)
    expected_nees = nees_series(dr, truth_trajectory(dataset))
    assert res.table.loc[0, "nees_mean"] == pytest.approx(expected_nees.mean, rel=1e-12)
    on_grid = nees_on_grid(expected_nees, dr.t_s[0], np.arange(res.nees_pose.shape[1]))
    np.testing.assert_allclose(res.nees_pose[0], on_grid, rtol=1e-12)


def test_runs_are_paired_with_dead_reckoning_by_seed():
    """Share of seeds beating DR and gain in the mean, by hand: seeds 0-3 paired (EKF beats DR on
    0, 2, 3 by the ATE, on 0, 1, 3 aligned); seed 4 has no DR run, seed 5's EKF run failed."""
    table = pd.DataFrame(
        {
            "seed": [0, 0, 1, 1, 2, 2, 3, 3, 4, 5, 5],
            "backend": ["dr", "ekf"] * 4 + ["ekf", "dr", "ekf"],
            "ate_truth_mean_m": [2.0, 1.0, 2.0, 3.0, 4.0, 1.0, 4.0, 2.0, 9.0, 2.0, np.nan],
            "ate_truth_aligned_mean_m": [1.0, 0.5, 1.0, 0.5, 2.0, 2.5, 2.0, 1.0, 9.0, 1.0, np.nan],
            "wall_s": 1.0,
            "error": [""] * 10 + ["RuntimeError: lost"],
        }
    )
    paired = pair_with_baseline(table)
    ekf = paired[paired.backend == "ekf"].set_index("seed")
    np.testing.assert_array_equal(ekf.loc[[0, 1, 2, 3], "beats_dr"], [1.0, 0.0, 1.0, 1.0])
    np.testing.assert_allclose(ekf.loc[[0, 1, 2, 3], "gain_over_dr"], [0.5, -0.5, 0.75, 0.5])
    np.testing.assert_array_equal(ekf.loc[[0, 1, 2, 3], "beats_dr_aligned"], [1, 1, 0, 1])
    assert ekf.loc[[4, 5], ["beats_dr", "gain_over_dr", "dr_ate_m"]].isna().all().all()
    assert paired.loc[paired.backend == "dr", "beats_dr"].isna().all()
    empty = np.zeros((len(table), 0))
    summary = summarise(paired, empty, empty).set_index("config")
    assert (summary.loc["ekf", "runs"], summary.loc["ekf", "failed"]) == (5, 1)
    assert summary.loc["ekf", "dr_pairs"] == 4 and summary.loc["ekf", "beats_dr_seeds"] == 3
    assert summary.loc["ekf", "beats_dr_share"] == pytest.approx(0.75, abs=1e-12)
    assert summary.loc["ekf", "gain_over_dr"] == pytest.approx(1.0 - 7.0 / 12.0, abs=1e-12)
    assert summary.loc["ekf", "beats_dr_aligned_share"] == pytest.approx(0.75, abs=1e-12)
    assert summary.loc["ekf", "gain_over_dr_aligned"] == pytest.approx(0.25, abs=1e-12)
    # the baseline's own row: its truth ATE, no pairing
    assert summary.loc["dr", "ate_truth_mean_m"] == pytest.approx(2.8, abs=1e-12)
    assert np.isnan(summary.loc["dr", "beats_dr_share"])


def test_sweep_on_the_drift_world_scores_against_the_truth(tmp_path, capsys):
    """A tiny sweep of the drift world through the CLI: each run's ATE is against the true poses
    (DR's equals a direct evaluation), the summary pairs the EKF with DR seed by seed."""
    out, cache = tmp_path / "sweep", tmp_path / "sim"
    argv = ["sweep", "--world", "drift", "--seeds", "0-1", "--backend", "dr,ekf"]
    argv += ["--duration", "120", "--scheduler", "synchronous", "--out", str(out)]
    assert main(argv + ["--cache", str(cache), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "beats_dr_share" in printed and "4 runs (0 failed)" in printed
    table = pd.read_csv(out / "sweep.csv")
    for seed in (0, 1):
        dataset = open_dataset(cache / f"drift_{seed}_120s")
        assert dataset.truth is not None and dataset.truth["kind"] == "drift"
        dr = table[(table.seed == seed) & (table.backend == "dr")].iloc[0]
        expected = ate_against_truth(dead_reckoning_trajectory(dataset), truth_trajectory(dataset))
        assert dr["ate_truth_mean_m"] == pytest.approx(expected.ate_mean_m, rel=1e-12)
        ekf = table[(table.seed == seed) & (table.backend == "ekf")].iloc[0]
        assert ekf["dr_ate_m"] == pytest.approx(dr["ate_truth_mean_m"], rel=1e-12)
        assert ekf["beats_dr"] == float(ekf["ate_truth_mean_m"] < dr["ate_truth_mean_m"])
    summary = pd.read_csv(out / "summary.csv").set_index("config")
    ekf_rows = table[table.backend == "ekf"]
    assert summary.loc["ekf", "beats_dr_share"] == pytest.approx(ekf_rows["beats_dr"].mean())
    assert summary.loc["ekf", "gain_over_dr"] == pytest.approx(
        1.0 - ekf_rows["ate_truth_mean_m"].mean() / ekf_rows["dr_ate_m"].mean(), rel=1e-9
    )
    assert summary.loc["ekf", "ate_truth_aligned_mean_m"] == pytest.approx(
        ekf_rows["ate_truth_aligned_mean_m"].mean(), rel=1e-9
    )
    assert (out / "sweep.png").stat().st_size > 10_000


def _synthetic_table(n: int = 10) -> pd.DataFrame:
    """DR and iSAM2 (online and smoothed) ATEs on ``n`` seeds, with known gains."""
    rng = np.random.default_rng(3)
    dr = rng.uniform(2.0, 6.0, n)
    online, smoothed = dr * rng.uniform(0.6, 1.2, n), dr * rng.uniform(0.3, 1.05, n)
    rows = []
    for s in range(n):
        rows.append(
            {
                "seed": s,
                "backend": "dr",
                "ate_truth_mean_m": dr[s],
                "ate_truth_aligned_mean_m": dr[s] / 3,
                "wall_s": 0.1,
                "error": "",
            }
        )
        rows.append({"seed": s, "backend": "isam2", "ate_truth_mean_m": online[s],
                     "ate_truth_aligned_mean_m": online[s] / 4,
                     "ate_truth_smoothed_mean_m": smoothed[s],
                     "ate_truth_aligned_smoothed_mean_m": smoothed[s] / 5,
                     "wall_s": 5.0, "error": "", "world_basins": 1 + s % 3})  # fmt: skip
    return pd.DataFrame(rows)


def test_summary_gives_the_spread_and_a_row_for_the_smoothed_trajectory():
    table = pair_with_baseline(_synthetic_table())
    summary = summarise(table, np.zeros(0), np.zeros(0)).set_index("config")
    assert list(summary.index) == ["dr", "isam2", "isam2 smoothed"]
    dr = table[table.backend == "dr"].set_index("seed")["ate_truth_mean_m"]
    dr_aligned = table[table.backend == "dr"].set_index("seed")["ate_truth_aligned_mean_m"]
    loop = table[table.backend == "isam2"].set_index("seed")
    for config, col, aligned_col in (
        ("isam2", "ate_truth_mean_m", "ate_truth_aligned_mean_m"),
        ("isam2 smoothed", "ate_truth_smoothed_mean_m", "ate_truth_aligned_smoothed_mean_m"),
    ):
        rec = summary.loc[config]
        gain = 1.0 - loop[col] / dr
        gain_aligned = 1.0 - loop[aligned_col] / dr_aligned
        for q in (10, 50, 90):
            assert rec[f"gain_over_dr_p{q}"] == pytest.approx(np.percentile(gain, q), rel=1e-12)
            assert rec[f"gain_over_dr_aligned_p{q}"] == pytest.approx(
                np.percentile(gain_aligned, q), rel=1e-12
            )
        assert rec["gain_over_dr_min"] == pytest.approx(gain.min(), rel=1e-12)
        assert rec["beats_dr_seeds"] == int((gain > 0).sum())
        assert rec["worse_than_dr_by_10pct_seeds"] == int((gain < -0.10).sum())
        assert rec["ate_truth_mean_m"] == pytest.approx(loop[col].mean(), rel=1e-12)
    # the worst seeds of the smoothed trajectory, worst first, with their world
    worst = sweep_mod.worst_seeds(table, "isam2 smoothed", 3)
    gain = (1.0 - loop["ate_truth_smoothed_mean_m"] / dr).sort_values()
    assert list(worst["seed"]) == list(gain.index[:3])
    assert list(worst["world_basins"]) == [1 + s % 3 for s in gain.index[:3]]
    text = sweep_mod.format_spread(summary.reset_index(), table, "synthetic", "a note")
    assert "| isam2 smoothed | 10 |" in text and "The 3 worst seeds" not in text
    assert "The 5 worst seeds of isam2 smoothed" in text and "a note" in text


def test_held_back_seeds_are_named_in_the_report():
    assert "held back" in held_back_note(list(range(10000, 10050)), 10000)
    assert "tuning seeds" in held_back_note([0, 1], 10000)
    assert "1 of 2 seeds" in held_back_note([0, 10000], 10000)


def test_sweep_of_drawn_worlds_reports_the_spread_and_draws_the_worlds(tmp_path, capsys):
    """The default world is drawn per seed: two tuning seeds differ in their walls, the rows
    carry each world's geometry, spread.md and worlds.png are written."""
    out, cache = tmp_path / "sweep", tmp_path / "sim"
    argv = ["sweep", "--seeds", "1-2", "--backend", "dr,isam2", "--duration", "60"]
    argv += ["--scheduler", "synchronous", "--out", str(out), "--cache", str(cache), "--quiet"]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "isam2 smoothed" in printed and "tuning seeds" in printed
    table = pd.read_csv(out / "sweep.csv")
    assert set(table["world"]) == {"drawn"} and table["world_basins"].notna().all()
    walls = [open_dataset(cache / f"drawn_{s}_60s").truth["walls_m"] for s in (1, 2)]
    assert walls[0] != walls[1]
    assert "## The 2 worst seeds of isam2 smoothed" in (out / "spread.md").read_text()
    assert (out / "worlds.png").stat().st_size > 10_000


@pytest.mark.parametrize("bias_deg", [0.0, 3.0])
def test_the_gauge_floor_is_the_start_pose_error_carried_over_the_run(tmp_path, bias_deg):
    """Without GPS and AHRS noise the estimators' start pose is off by the AHRS's constant bias
    alone, so the floor is the truth turned by that bias about the start: the mean distance
    from the start times 2 sin(bias / 2)."""
    sc = make_scenario("drawn", 7, 120.0)
    assert sc.errors is not None
    noise = replace(sc.noise, gps_sigma_m=1e-6, ahrs_sigma_deg=0.0, ahrs_bias_deg=bias_deg)
    errors = replace(sc.errors, ahrs_heading_walk_deg_per_sqrt_s=0.0, ahrs_heading_field_deg=0.0)
    sim = simulate_records(replace(sc, noise=noise, errors=errors))
    dataset = open_dataset(write_dataset(sim, tmp_path))
    truth = truth_trajectory(dataset)
    poses = truth.poses(truth.t_s)
    start = truth.poses([dataset.gps.t[0]])[0]
    turn = 2.0 * np.sin(np.radians(bias_deg) / 2.0)
    expected = float(np.mean(np.hypot(*(poses[:, :2] - start[:2]).T))) * turn
    assert sweep_mod.gauge_ate_m(dataset) == pytest.approx(expected, abs=0.01)
