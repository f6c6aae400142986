"""The run directory as other tools read it: evo's own CLI scores the TUM files exactly as
metrics.json, GTSAM's readG2o loads graph.g2o, every file and every metrics.json key is in the
table of docs/outputs.md, and metrics.json records where its figures come from. (The Python
examples of the README and docs/ are run by tests/test_docs_examples.py.)"""

from __future__ import annotations

import fnmatch
import itertools
import json
import re
import subprocess
import sys
import warnings
from pathlib import Path

import gtsam
import numpy as np
import pytest
from matplotlib.figure import Figure

from sonarslam.datasets.simulator import simulate
from sonarslam.datasets.source import open_dataset
from sonarslam.slam.backends.isam2.g2o import G2O_EDGE_TYPES, graph_json_to_g2o
from sonarslam.slam.backends.isam2.graph_io import FactorRecord, key_of, load_graph
from sonarslam.slam.eval.ate import ate_against_gps, ate_errors, truth_errors
from sonarslam.slam.eval.truth import truth_trajectory
from sonarslam.slam.io.maps import MapLayers, draw_map, trajectory_style
from sonarslam.slam.io.plots import ate_legend
from sonarslam.slam.run.metrics import RunMetrics
from sonarslam.slam.run.run import run

ROOT = Path(__file__).resolve().parents[1]
EVO_APE = Path(sys.executable).parent / "evo_ape"


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """dr and isam2 on a short simulated harbour (isam2 also writes its smoothed trajectory and
    its graph, and learns its noise: ``noise.csv``)."""
    root = tmp_path_factory.mktemp("outputs")
    source = simulate("harbour", seed=3, out_dir=root / "h3", duration_s=150.0)
    learn = {"isam2.learn_noise": "heading,dvl_scale,lines", "isam2.learn_every": 2}
    with warnings.catch_warnings():  # what graph.g2o leaves out is a note, not a warning
        warnings.filterwarnings("error", message=".*g2o cannot hold")
        isam2 = run(source, "isam2", root / "isam2", settings=learn, progress=False)
    assert (isam2.out_dir / "noise.csv").is_file()
    assert "noise_line_scale_final" in isam2.metrics
    assert any("g2o cannot hold" in n and "HeadingBias" in n for n in isam2.notes), isam2.notes
    return {"dr": run(source, "dr", root / "dr", progress=False), "isam2": isam2}


def _evo_ape(run_dir: Path, reference: str, estimate: str) -> dict[str, float]:
    """``evo_ape tum REFERENCE ESTIMATE`` as typed (no option), its statistics parsed."""
    out = subprocess.run(
        [str(EVO_APE), "tum", reference, estimate],
        cwd=run_dir,
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    ).stdout
    return {
        k: float(v) for k, v in re.findall(r"^\s*(max|mean|min|rmse|std)\s+([0-9.]+)", out, re.M)
    }


@pytest.mark.skipif(not EVO_APE.is_file(), reason="evo's CLI is not installed beside python")
@pytest.mark.parametrize(
    ("backend", "estimate", "key"),
    [
        ("dr", "dr.tum", "ate_{}_m"),
        ("isam2", "isam2.tum", "ate_{}_m"),
        ("isam2", "isam2_smoothed.tum", "ate_{}_smoothed_m"),
    ],
)
def test_plain_evo_ape_prints_the_metrics_ate(runs, backend, estimate, key):
    """Against gps.tum, evo's default association (10 ms) pairs every GPS fix with the estimate
    interpolated there: the whole-run ATE of metrics.json to well under 1 cm."""
    r = runs[backend]
    stats = _evo_ape(r.out_dir, "gps.tum", estimate)
    assert stats["mean"] == pytest.approx(r.metrics[key.format("mean")], abs=1e-4)
    assert stats["max"] == pytest.approx(r.metrics[key.format("max")], abs=1e-4)
    if key == "ate_{}_m":
        assert stats["rmse"] == pytest.approx(r.metrics["ate_rmse_m"], abs=1e-4)
        assert stats["min"] == pytest.approx(r.metrics["ate_min_m"], abs=1e-4)


@pytest.mark.skipif(not EVO_APE.is_file(), reason="evo's CLI is not installed beside python")
def test_plain_evo_ape_against_the_truth(runs):
    r = runs["isam2"]
    stats = _evo_ape(r.out_dir, "truth.tum", "isam2.tum")
    assert stats["mean"] == pytest.approx(r.metrics["ate_truth_mean_m"], abs=1e-4)


def test_read_g2o_loads_the_pose_graph(runs):
    """graph.g2o: every pose at the estimate and every odometry factor as a BetweenFactorPose2
    whose error at the estimate is the odometry factor's (first-order equivalent)."""
    out = runs["isam2"].out_dir
    doc = json.loads((out / "graph.json").read_text())
    graph, values = gtsam.readG2o(str(out / "graph.g2o"), False)
    poses = {k: v for k, v in doc["values"].items() if v["type"] == "Pose2"}
    odometry = [f for f in doc["factors"] if f["type"] in G2O_EDGE_TYPES]
    assert values.size() == len(poses) >= 20
    assert graph.size() == len(odometry)
    for name, item in poses.items():
        p = values.atPose2(int(name[1:]))
        np.testing.assert_allclose([p.x(), p.y(), p.theta()], item["value"], atol=1e-9)
    _, json_values = load_graph(out / "graph.json")
    # an edge whose factor estimates the DVL misalignment D(0) or scale K(0) (a scale per node
    # K(k) when its walk is learned) is written at delta = 0, k = 0 (g2o has no scalar
    # variable): ours evaluated there
    at_written = gtsam.Values(json_values)
    for key in at_written.keys():
        if chr(gtsam.Symbol(key).chr()) in "dk":
            at_written.update(key, np.zeros(1))
    ours = sum(FactorRecord.from_json(f).to_gtsam().error(at_written) for f in odometry)
    assert graph.error(values) == pytest.approx(ours, rel=1e-3)
    # a GTSAM user's re-optimisation: fix the first pose and run Levenberg-Marquardt
    graph.add(
        gtsam.PriorFactorPose2(0, values.atPose2(0), gtsam.noiseModel.Isotropic.Sigma(3, 1e-3))
    )
    result = gtsam.LevenbergMarquardtOptimizer(graph, values).optimize()
    assert graph.error(result) <= graph.error(values) + 1e-9
    assert key_of("x0") == gtsam.symbol("x", 0)


def test_g2o_export_warns_what_it_leaves_out(runs, tmp_path):
    out = runs["isam2"].out_dir
    with pytest.warns(UserWarning, match=r"g2o cannot hold .*LineObservation") as record:
        export = graph_json_to_g2o(out / "graph.json", tmp_path / "g.g2o")
    assert "graph.json has the whole graph" in str(record[0].message)
    lines = sum(n for kind, n in export.left_out.items() if kind.startswith("LineObservation"))
    assert lines > 0 and export.edges > 0


def _outputs_page() -> str:
    return (ROOT / "docs" / "outputs.md").read_text()


def test_every_output_file_is_in_the_docs_table(runs):
    """Each file a run writes matches a name of docs/outputs.md's table (``<backend>`` stands
    for the back end's name)."""
    text = _outputs_page()
    table = text[text.index("# Outputs") :]
    names = re.findall(r"^\| `([^`]+)`", table, re.M)
    patterns = [re.sub(r"<[^>]+>", "*", n) for n in names]
    for r in runs.values():
        for f in r.out_dir.iterdir():
            assert any(fnmatch.fnmatch(f.name, p) for p in patterns), (
                f"{f.name} not in docs/outputs.md"
            )
    # and every key of metrics.json is in its table (``*``, ``<name>``, ``{a,b}`` as patterns)
    keys_part = table[table.index("`metrics.json` (one object") : table.index("## With evo")]
    key_patterns = []
    for token in re.findall(r"`([^`]+)`", keys_part):
        token = re.sub(r"<[^>]+>", "*", token)
        pieces = re.split(r"\{([^}]*)\}", token)  # text, alternatives, text, ...
        choices = [[p] if i % 2 == 0 else p.split(",") for i, p in enumerate(pieces)]
        key_patterns += ["".join(c) for c in itertools.product(*choices)]
    for r in runs.values():
        for key in r.metrics:
            assert any(fnmatch.fnmatch(key, p) for p in key_patterns), (
                f"{key} not in docs/outputs.md"
            )


def test_the_docs_trajectories_picture_row_names_every_estimate_drawn(runs):
    """``<name>_trajectories.png`` draws each run's every trajectory (demo.main_job): the row of
    docs/outputs.md names each an isam2 run makes (a review: it left out the offline one)."""
    text = _outputs_page()
    row = next(line for line in text.splitlines() if line.startswith("| `<name>_trajectories"))
    drawn = row[row.index("every estimate of the runs (") :].split(")")[0]
    assert {"smoothed", "offline"} <= set(runs["isam2"].trajectories)
    for name in [*runs["isam2"].trajectories, "batch"]:  # batch: demo runs isam2 with --batch
        assert name in drawn, (name, drawn)


def test_the_docs_key_table_is_the_keys_run_metrics_writes():
    """docs/outputs.md's ``metrics.json`` table names exactly the keys (and key patterns) of
    :class:`sonarslam.slam.run.metrics.RunMetrics`' records, both ways."""
    text = _outputs_page()
    part = text[text.index("`metrics.json` (one object") : text.index("## With evo")]
    rows = re.findall(r"^\| (`[^|]+`) \|", part, re.M)
    documented = {token for row in rows for token in re.findall(r"`([^`]+)`", row)}
    assert len(documented) > 60
    declared = RunMetrics.key_patterns()
    assert documented - declared == set(), "in the docs, not in RunMetrics"
    assert declared - documented == set(), "in RunMetrics, not in the docs"


def test_metrics_record_the_code_settings_and_data_of_the_run(runs):
    """metrics.json's provenance: the package version, the commit of this tree and whether it
    was dirty, the settings' digest, and the SHA-256 of every file of the dataset."""
    import hashlib
    from importlib.metadata import version

    from sonarslam.slam.run.provenance import settings_digest

    r = runs["isam2"]
    p = json.loads((r.out_dir / "metrics.json").read_text())["provenance"]
    assert p["version"] == version("sonarslam")
    if (ROOT / ".git").exists():
        head = subprocess.run(
            ["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True
        ).stdout.strip()
        assert p["git_commit"] == head and isinstance(p["git_dirty"], bool)
    source = Path(r.metrics["source"])
    files = sorted(f for f in source.rglob("*") if f.is_file())
    assert p["dataset_file_count"] == len(files) >= 6
    for f in files:  # a simulated run: few files, each listed with its digest
        rel = f.relative_to(source).as_posix()
        assert p["dataset_files"][rel] == hashlib.sha256(f.read_bytes()).hexdigest()
    assert re.fullmatch(r"[0-9a-f]{64}", p["settings_sha256"])
    # the digest follows the settings (config_used.toml's, below the lines that say which of
    # them the back end takes for its start pose only): another back-end setting, another digest
    config_text = (r.out_dir / "config_used.toml").read_text()
    config_text = config_text[config_text.index("\n", config_text.index("# the start pose")) + 1 :]
    mine = settings_digest("isam2", config_text, r.config)
    assert mine == p["settings_sha256"]
    from dataclasses import replace

    other = replace(r.config, settings={"isam2.robust": "cauchy"})
    assert settings_digest("isam2", config_text, other) != mine
    assert settings_digest("isam2", config_text + "\n# edited", r.config) != mine
    assert runs["dr"].metrics["provenance"]["dataset_sha256"] == p["dataset_sha256"]


def test_report_png_legend_gives_the_metrics_figures_over_each_named_span(runs):
    """report.png's legend (:func:`ate_legend`) names its spans and gives metrics.json's figures:
    against GPS the whole run's (``ate_*``), the smoothed trajectory's too, and the sonar
    span's (``ate_sonar_*``: here every fix, so one figure says so; over a part of the run, the
    part's); against the truth the whole run's (``ate_truth_*``)."""
    isam2 = runs["isam2"]
    dataset = open_dataset(isam2.out_dir.parent / "h3")
    span = dataset.sonar_span_s
    assert span is not None
    m = isam2.metrics
    assert m["ate_sonar_n"] == m["ate_n"]  # the sonar runs from the first fix to the last
    for name, tr in [("", isam2.trajectory), ("_smoothed", isam2.trajectories["smoothed"])]:
        legend = ate_legend("iSAM2", *ate_errors(tr, dataset.gps), span)
        assert m[f"ate_sonar{name}_mean_m"] == m[f"ate_mean{name}_m"]
        whole = m[f"ate_mean{name}_m"], m[f"ate_max{name}_m"]
        assert legend == (
            f"iSAM2: whole run mean {whole[0]:.2f} m, max {whole[1]:.2f} m (all of it in the"
            " sonar span)"
        )
    part = (span[0] + 30.0, span[1] - 40.0)
    inside = ate_against_gps(isam2.trajectory, dataset.gps, part)
    legend = ate_legend("iSAM2", *ate_errors(isam2.trajectory, dataset.gps), part)
    assert legend == (
        f"iSAM2: sonar span mean {inside.ate_mean_m:.2f} m, max {inside.ate_max_m:.2f} m;"
        f" whole run mean {m['ate_mean_m']:.2f} m, max {m['ate_max_m']:.2f} m"
    )
    truth = truth_trajectory(dataset)
    legend = ate_legend("iSAM2", *truth_errors(isam2.trajectory, truth))
    assert legend == (
        f"iSAM2: whole run mean {m['ate_truth_mean_m']:.2f} m, max {m['ate_truth_max_m']:.2f} m"
    )


def test_estimates_drawn_together_differ_in_colour_and_line_style():
    """Dead reckoning and every closed-loop estimate (report.png, the demo's trajectories.png)
    differ from one another in colour and from dead reckoning and the reference in line style
    too; the colours are Okabe and Ito's, which stay apart for colour-blind readers."""
    okabe_ito = {
        "#000000",
        "#E69F00",
        "#56B4E9",
        "#009E73",
        "#F0E442",
        "#0072B2",
        "#D55E00",
        "#CC79A7",
    }
    estimates = ["dr", "ekf", "isam2", "isam2_smoothed", "isam2_batch"]
    styles = [trajectory_style(n) for n in estimates]
    assert len({s.colour for s in styles}) == len(styles)
    assert {s.colour for s in styles} <= okabe_ito
    dr, gps = trajectory_style("dr"), trajectory_style("gps")
    assert all(s.linestyle not in (dr.linestyle, gps.linestyle) for s in styles[1:])
    assert trajectory_style("other").label == "other"


def test_map_png_writes_each_landmark_id_by_its_segment():
    """map.png names each landmark by its map.json id, at the middle of its segment."""
    segments = [np.array([[0.0, 0.0], [10.0, 0.0]]), np.array([[0.0, 5.0], [0.0, 15.0]])]
    layers = MapLayers(np.zeros((0, 2)), segments_w=segments, segment_ids=[3, 17])
    ax = Figure().subplots()
    draw_map(ax, layers, (np.array([-5.0, -5.0]), np.array([20.0, 20.0])))
    assert {(t.get_text(), tuple(np.round(t.xy, 6))) for t in ax.texts} == {
        ("3", (5.0, 0.0)),
        ("17", (0.0, 10.0)),
    }


def test_a_map_shows_every_landmark_and_bin_it_draws():
    """A run's map stopped at ~7 m, where its bins were dense, with its one landmark at 15 m
    cut out (issue 41): the box holds every segment, every bin and the trajectory drawn."""
    from sonarslam.slam.io.maps import data_box
    from sonarslam.slam.io.trajectory import Trajectory

    rng = np.random.default_rng(41)
    bins = rng.uniform(-7.0, 7.0, (5000, 2))
    stray = np.array([[-12.0, 3.0]])  # one bin far from the rest
    landmark = np.array([[15.0, -4.0], [15.0, 4.0]])
    track = Trajectory(np.array([0.0, 1.0]), np.array([[0.0, 0.0, 0.0], [1.0, 0.5, 0.0]]))
    layers = MapLayers(np.concatenate([bins, stray]), {"dr": track}, [landmark], segment_ids=[0])
    lo, hi = data_box(layers)
    assert np.all(lo <= [-12.0, -7.0]) and np.all(hi >= [15.0, 7.0])
    assert np.all(lo >= [-12.0 - 1.5, -7.0 - 1.5]) and np.all(hi <= [15.0 + 1.5, 7.0 + 1.5])
    ax = Figure().subplots()
    draw_map(ax, layers, (lo, hi))
    assert ax.get_xlim()[1] >= 15.0 and [t.get_text() for t in ax.texts] == ["0"]


def test_provenance_of_a_single_file_source_digests_what_the_run_reads(tmp_path: Path) -> None:
    """A Ping Viewer log (or a bag file): the file, the sonarslam.toml and truth.json beside it
    and its navigation elsewhere (a bag directory), each by its bytes; not the folder's other
    files."""
    import hashlib

    from sonarslam.slam.run.provenance import dataset_digests

    folder, nav = tmp_path / "logs", tmp_path / "nav"
    (nav / "bag").mkdir(parents=True)
    folder.mkdir()
    for path, text in [
        (folder / "log.bin", b"pings"),
        (folder / "sonarslam.toml", b"[sonar]\n"),
        (folder / "truth.json", b"{}"),
        (folder / "notes.txt", b"not read"),
        (nav / "bag" / "metadata.yaml", b"m"),
        (nav / "bag" / "bag_0.db3", b"d"),
    ]:
        path.write_bytes(text)
    total, listed, count = dataset_digests(folder / "log.bin", [nav / "bag"])

    def sha(p: Path) -> str:
        return hashlib.sha256(p.read_bytes()).hexdigest()

    outside = (nav / "bag").resolve().as_posix()
    assert listed == {
        "log.bin": sha(folder / "log.bin"),
        "sonarslam.toml": sha(folder / "sonarslam.toml"),
        "truth.json": sha(folder / "truth.json"),
        f"{outside}/bag_0.db3": sha(nav / "bag" / "bag_0.db3"),
        f"{outside}/metadata.yaml": sha(nav / "bag" / "metadata.yaml"),
    }
    assert count == 5 and total != hashlib.sha256().hexdigest()
    (folder / "log.bin").write_bytes(b"other pings")
    assert dataset_digests(folder / "log.bin", [nav / "bag"])[0] != total


def test_the_association_counts_add_up_and_the_nees_is_recorded(runs):
    """metrics.json's association counters reconcile (docs/outputs.md: every line the landmark
    layer used is paired or unpaired, every unpaired one seeded a landmark, was dropped with
    its tentative line or still waits; issue 32's review could not find 2 of 61), and a
    simulated closed loop records its pose, position and heading NEES against the truth with
    their chi2 bands (the report computed it; metrics.json had none)."""
    from sonarslam.slam.eval.consistency import chi2_band, nees_series
    from sonarslam.slam.io.trajectory import load_run_trajectory

    m = runs["isam2"].metrics
    assert m["assoc_observations"] > 0 and m["assoc_unpaired"] > 0
    assert m["assoc_observations"] == m["assoc_associated"] + m["assoc_unpaired"]
    assert m["assoc_unpaired"] == (
        m["assoc_seed_observations"]
        + m["assoc_tentative_dropped_observations"]
        + m["assoc_tentative_pending_observations"]
    )
    assert 0 <= m["assoc_reobservations_skipped"] <= m["assoc_associated"]
    assert m["assoc_seed_observations"] >= m["assoc_new_landmarks"]
    assert m["line_features"] >= m["assoc_observations"] + m["assoc_rejected_near"]
    # the NEES of the run's own trajectory, as the report's nees_series gives it
    out = runs["isam2"].out_dir
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        truth = truth_trajectory(open_dataset(m["source"]))
    estimate = load_run_trajectory(out, "isam2")
    for block, dof in (("pose", 3), ("position", 2), ("heading", 1)):
        series = nees_series(estimate, truth, block)
        # (the TUM file holds the poses to its printed digits)
        assert m[f"nees_{block}_mean"] == pytest.approx(series.mean, rel=1e-3)
        assert m[f"nees_{block}_in_band_fraction"] == pytest.approx(
            series.in_band_fraction(), abs=0.01
        )
        assert m[f"nees_{block}_band"] == pytest.approx(list(chi2_band(dof)))
    assert 0.0 < m["nees_pose_mean"] < 50.0
    # dead reckoning's own covariances (not written to a file) give its NEES too
    assert runs["dr"].metrics["nees_pose_mean"] > 0.0
