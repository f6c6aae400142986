"""The sonar mounting yaw from the map's sharpness (slam.run.calibration.calibrate_sonar_yaw,
``sonarslam calibrate``), against the simulator's true mounting: the yaw found is the truth's,
or the objective is reported flat and the command refuses; never a wrong yaw with exit 0."""

from __future__ import annotations

import json
import math
import tomllib
from collections.abc import Callable
from pathlib import Path

import pytest

from sonarslam.datasets.errors import DataWarning
from sonarslam.datasets.source import Dataset, open_dataset
from sonarslam.features.geometry import wrap_angle
from sonarslam.slam.cli import calibrate as calibrate_cli
from sonarslam.slam.cli.main import main
from sonarslam.slam.eval.truth import true_sonar
from sonarslam.slam.run.calibration import (
    MIN_YAW_DEPTH,
    MIN_YAW_MARGIN,
    YawSearch,
    calibrate_sonar_yaw,
)
from sonarslam.slam.run.sources import pose_source_by_name
from tests.echoes import shuffled_echoes

#: Tolerance (deg) on the yaw found: the fine grid's step is 0.25 deg, the dead-reckoning
#: heading of a 120 s window errs by about a degree (AHRS bias 2 deg, sigma 0.5 deg).
YAW_TOL_DEG = 3.0


@pytest.fixture(scope="module")
def harbour(simulated: Callable[..., Path]) -> Dataset:
    """300 s of the harbour world (raw intensities with background noise, sonar yaw 180 deg)."""
    return open_dataset(simulated("harbour", 2, 300.0))


@pytest.fixture(scope="module")
def harbour_search(harbour: Dataset) -> YawSearch:
    return calibrate_sonar_yaw(harbour, pose_source_by_name(harbour, "dr"))


def test_sonar_yaw_of_the_harbour_is_the_truth(harbour: Dataset, harbour_search: YawSearch) -> None:
    """Raw beams: the echoes (bins at the extractor's threshold) are scored, not the background
    noise that made the objective flat (30.68 vs 30.75 nats over 360 deg, least at 22 deg)."""
    truth = true_sonar(harbour)[0][2]
    err = math.degrees(abs(wrap_angle(harbour_search.best_yaw_rad - truth)))
    assert err < YAW_TOL_DEG, (math.degrees(harbour_search.best_yaw_rad), math.degrees(truth))
    assert harbour_search.decisive, harbour_search.verdict()
    # seeds 1-4 gave depth 17-30 and margin 12-21 noise units, the shuffled echoes <= 3.1 and
    # <= 1.1, the marina 9.7 and 7.2
    assert harbour_search.depth > 2 * MIN_YAW_DEPTH
    assert harbour_search.margin > 2 * MIN_YAW_MARGIN


def test_sonar_yaw_without_geometry_is_not_decisive(harbour: Dataset) -> None:
    """Echoes shuffled among the beams: the objective is flat and says so."""
    ds = shuffled_echoes(harbour, seed=7)
    search = calibrate_sonar_yaw(ds, pose_source_by_name(ds, "dr"))
    assert not search.decisive, search.verdict()
    assert search.depth < MIN_YAW_DEPTH or search.margin < MIN_YAW_MARGIN


def test_calibrate_cli_yaw_or_refusal(
    harbour: Dataset,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """The command prints the true yaw with exit 0, or refuses (exit 1, one line, nothing
    written) when the objective is flat."""
    out = tmp_path / "sonarslam.toml"
    assert main(["calibrate", str(harbour.root), "--write", str(out)]) == 0
    line = [s for s in capsys.readouterr().out.splitlines() if "sonar mounting yaw" in s][0]
    found = float(line.split("poses: ")[1].split(" deg")[0])
    truth = math.degrees(true_sonar(harbour)[0][2])
    assert abs((found - truth + 180.0) % 360.0 - 180.0) < YAW_TOL_DEG, line
    assert out.is_file()

    flat = shuffled_echoes(harbour, seed=7)
    monkeypatch.setattr(calibrate_cli, "open_dataset", lambda *a, **k: flat)
    refused = tmp_path / "refused.toml"
    assert main(["calibrate", str(harbour.root), "--write", str(refused)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "too flat to give a sonar yaw" in err[0], err
    assert "nothing written" in err[0]
    # a mirrored sonar flattens the objective too: the refusal names it (issue 32's review)
    assert "[sonar] angle_sense" in err[0]
    assert not refused.exists()


@pytest.fixture(scope="module")
def harbour_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """300 s of the harbour (seed 1) as a ROS 1 bag without GPS (the odometry check's case),
    with the simulator's sonarslam.toml (sonar yaw 180 deg, DVL yaw -90 deg) and truth.json."""
    out = tmp_path_factory.mktemp("harbour_bag")
    args = ["simulate", "harbour", "--seed", "1", "--duration", "300", "--out", str(out)]
    assert main([*args, "--bag", "ros1", "--no-gps"]) == 0
    return out / "sim_harbour_1.bag"


def _bag_copy(bag: Path, folder: Path, toml: str | None) -> Path:
    """The bag alone in ``folder`` (no truth.json: a user's run, judged GPS-free), with ``toml``
    as its sonarslam.toml when given."""
    folder.mkdir()
    copy = folder / bag.name
    copy.write_bytes(bag.read_bytes())
    if toml is not None:
        (folder / "sonarslam.toml").write_text(toml, encoding="utf-8")
    return copy


def _calibrated_yaw_deg(toml: Path) -> float:
    data = tomllib.loads(toml.read_text(encoding="utf-8"))
    return float(data["mounting"]["sonar"]["yaw_deg"])


def test_calibrate_does_not_take_a_dvl_turned_round_for_the_sonar(
    harbour_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The DVL's yaw given 180 deg wrong: dead reckoning runs stern first, and the sharpest map
    has the sonar turned 180 deg too (its yaw relative to the motion is right). calibrate used to
    write that yaw silently (0.5 deg for the true 180; the rerun then said "no inconsistency
    found" at an ATE of 53 m): it refuses (exit 1, nothing written), naming the DVL and AHRS
    mountings and dead reckoning's stern-first travel. Written all the same
    (--accept-large-yaw), the rerun's health monitor flags the travel."""
    toml = (harbour_bag.parent / "sonarslam.toml").read_text(encoding="utf-8")
    assert 'yaw_deg = -90.0\nsource = "simulator truth"' in toml  # the DVL's table
    wrong = toml.replace(
        'yaw_deg = -90.0\nsource = "simulator truth"', 'yaw_deg = 90.0\nsource = "drawing"'
    )
    bag = _bag_copy(harbour_bag, tmp_path / "run", wrong)
    out = tmp_path / "written.toml"
    assert main(["calibrate", str(bag), "--quiet", "--write", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "nothing written" in err and not out.exists(), err
    for named in ("[mounting.dvl] yaw_deg", "[mounting.ahrs] yaw_deg", "--accept-large-yaw"):
        assert named in err, (named, err)
    assert "+180 deg off its bow" in err, err

    assert main(["calibrate", str(bag), "--quiet", "--accept-large-yaw", "--write", str(out)]) == 0
    assert abs(wrap_angle(math.radians(_calibrated_yaw_deg(out)))) < math.radians(YAW_TOL_DEG)
    (bag.parent / "sonarslam.toml").write_text(out.read_text(encoding="utf-8"), encoding="utf-8")
    run_dir = tmp_path / "ekf"
    assert main(["run", str(bag), "--backend", "ekf", "--quiet", "--out", str(run_dir)]) == 0
    metrics = json.loads((run_dir / "metrics.json").read_text(encoding="utf-8"))
    assert abs(metrics["odometry_check_heading_deg"]) < 10.0  # the sonar agrees with the DVL
    assert "travel" in metrics["health_flagged"], metrics["health_line"]
    assert not metrics["health_line"].startswith("health: no inconsistency found")


def test_calibrate_names_the_sonar_when_dead_reckoning_runs_bow_first(
    harbour_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The sonar's yaw given 180 deg wrong, the DVL right: calibrate still refuses a change that
    large without --accept-large-yaw, but its words follow its own evidence: dead reckoning runs
    bow first, so the DVL's mounting looks right and the sonar's is the likely one (it said a
    rotation this large is more likely the DVL's or the AHRS's)."""
    toml = (harbour_bag.parent / "sonarslam.toml").read_text(encoding="utf-8")
    sonar = tomllib.loads(toml)["mounting"]["sonar"]["yaw_deg"]
    head, tail = toml.split("[mounting.sonar]", 1)
    tail = tail.replace(f"yaw_deg = {sonar!r}", f"yaw_deg = {sonar - 180.0!r}", 1)
    bag = _bag_copy(harbour_bag, tmp_path / "run", head + "[mounting.sonar]" + tail)
    assert main(["calibrate", str(bag), "--quiet"]) == 1
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "sonar's configured yaw is the likely one at fault" in err, err
    assert "more likely one of those" not in err and "--accept-large-yaw" in err, err


def test_calibrate_keeps_the_mountings_it_assumed_assumed(
    harbour_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A bag without sonarslam.toml: every mounting is the identity. The sharpest map's sonar
    yaw is then relative to the DVL's assumed mounting (-90 deg for the true 180 and DVL -90):
    calibrate says so, and its --write keeps the DVL's and AHRS's mountings marked as assumed,
    so that the next opening still warns of them (it used to write them as given: silence, at
    an ATE of 37 m)."""
    bag = _bag_copy(harbour_bag, tmp_path / "run", None)
    out = bag.parent / "sonarslam.toml"
    assert main(["calibrate", str(bag), "--quiet", "--write", str(out)]) == 0
    said = capsys.readouterr().err  # the command prints its warnings
    assert "the DVL and AHRS mounting(s) are assumed" in said, said
    assert "may be the DVL's mounting, not the sonar's" in said, said
    assert "+90 deg off its bow" in said, said
    with pytest.warns(DataWarning, match=r"the dvl, ahrs mounting\(s\) are the identity, assumed"):
        ds = open_dataset(bag)
    assert ds.config.dvl_mounting.assumed and ds.config.ahrs_mounting.assumed
    assert not ds.config.sonar_mounting.assumed
