"""Issue "Never wrong in silence": each case a user hit gives a clear line or a counted
warning (docs/bad-input.md): what a kill leaves, settings refused late, the docs' rules
against the code, thin overlaps, one-row logs, a full disk, bounded memory, the health monitor
end to end."""

from __future__ import annotations

import errno
import os
import re
import shutil
import subprocess
import sys
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from sonarslam.datasets.errors import DataError, DataWarning
from sonarslam.datasets.keyframes import read_keyframe_times, read_pcd
from sonarslam.datasets.logfile import NUMBER, iter_tables, read_table
from sonarslam.datasets.source import open_dataset
from sonarslam.slam.cli.main import main
from sonarslam.slam.io.files import atomic_path, make_output_dir, remove_stale_temporaries
from tests.fuzz_inputs import edit_log_rows

#: Where the docs state the readers' rules (README.md links it).
BAD_INPUT = Path(__file__).resolve().parents[1] / "docs" / "bad-input.md"


@pytest.fixture(scope="module")
def harbour(simulated: Callable[..., Path]) -> Path:
    """100 s of harbour, seed 4 (simulated once per session: tests/test_faults.py and
    tests/test_never_silent.py read it); read only, a test that changes it copies it."""
    return simulated("harbour", 4, 100.0, name="h")


def _log(folder: Path, suffix: str) -> Path:
    return next(folder.glob(f"*_{suffix}.log"))


def _dead_pid() -> int:
    """The id of a process that has ended."""
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


# -- a kill during a write -----------------------------------------------------------------


def test_a_killed_writers_temporaries_are_removed_and_never_listed(harbour, tmp_path, capsys):
    """A SIGKILL runs no clean-up: the next run into the same --out removes its temporaries
    (their writer's pid is gone), keeps a running writer's, and lists only its own files."""
    out = tmp_path / "out"
    out.mkdir()
    dead = out / f".dr.tum.{_dead_pid()}-0123456789ab.part.tum"
    dead.write_text("half a trajectory")
    (out / f".part-{_dead_pid()}-0123456789ab").mkdir()
    alive = out / f".x.tum.{os.getpid()}-0123456789ab.part.tum"
    alive.write_text("being written")
    (out / "older_run.tum").write_text("another run's file")
    assert main(["run", str(harbour), "--backend", "dr", "--out", str(out), "--quiet"]) == 0
    listed = re.search(r"outputs: .* \((.*)\)", capsys.readouterr().out)
    assert listed is not None
    names = listed.group(1).split(", ")
    assert "dr.tum" in names and "metrics.json" in names
    assert "older_run.tum" not in names and not any(".part" in n for n in names)
    assert not dead.exists() and alive.exists()
    assert [p.name for p in out.iterdir() if p.name.startswith(".part-")] == []
    assert remove_stale_temporaries(out) == []  # nothing left to clean


def test_a_write_error_names_the_file(tmp_path):
    """Disk full: the error names the file being written, not only 'No space left'."""
    target = tmp_path / "metrics.json"
    with pytest.raises(OSError) as info, atomic_path(target):
        raise OSError(errno.ENOSPC, "No space left on device")
    assert info.value.filename == str(target) and info.value.errno == errno.ENOSPC
    assert list(tmp_path.iterdir()) == []
    make_output_dir(tmp_path / "o")  # a new directory has nothing to clean


# -- settings: one range, with file, key and line -----------------------------------------


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "[noise]\ndvl_scale_sigma = 0.5\n",
            r"t\.toml:2: \[noise\] dvl_scale_sigma: must be in \[0, 0\.5\)",
        ),
        (
            "[mounting.sonar]\nx_m = 1.0\ny_m = 179.9\n",
            r"t\.toml:3: \[mounting\.sonar\] y_m: must be in \[-10, 10\]",
        ),
        # unit slips: centimetres for metres, milliseconds for seconds
        (
            "[mounting.sonar]\nx_m = 30\nyaw_deg = 180.0\n",
            r"t\.toml:2: \[mounting\.sonar\] x_m: must be in \[-10, 10\], got 30",
        ),
        (
            "[sonar]\ntime_offset_s = 150\n",
            r"t\.toml:2: \[sonar\] time_offset_s: must be in \[-10, 10\], got 150",
        ),
    ],
)
def test_a_setting_out_of_range_names_the_file_key_and_line(
    harbour, tmp_path, capsys, text, message
):
    config = tmp_path / "t.toml"
    config.write_text(text)
    args = ["run", str(harbour), "--backend", "ekf", "--config", str(config), "--quiet"]
    assert main([*args, "--out", str(tmp_path / "o")]) == 1
    assert re.search(message, capsys.readouterr().err)


def test_the_back_ends_take_every_scale_sigma_the_file_takes():
    from sonarslam.datasets.config import DVL_SCALE_SIGMA_MAX, NoiseConfig
    from sonarslam.settings import SettingError
    from sonarslam.slam.backends.ekf import EkfConfig
    from sonarslam.slam.run.presets import apply_overrides

    top = np.nextafter(DVL_SCALE_SIGMA_MAX, 0.0)
    assert EkfConfig(noise=NoiseConfig(dvl_scale_sigma=top)).noise.dvl_scale_sigma == top
    with pytest.raises(SettingError, match=r"^ekf.noise.dvl_scale_sigma: must be in \[0, 0\.5\)"):
        apply_overrides(EkfConfig(), {"noise.dvl_scale_sigma": 0.5}, prefix="ekf.")


def test_isam2_refuses_the_gyro_with_a_walking_bias_up_front(harbour, tmp_path, capsys):
    """Only when the data show a gyro bias (measured against the AHRS heading's change): the
    simulated gyro with the marina MTi's 0.01 rad/s is refused, an unbiased one is not."""
    from dataclasses import replace

    from sonarslam.datasets.simulator import make_scenario, simulate_records
    from sonarslam.datasets.simulator.writer import write_dataset

    scenario = make_scenario("harbour", 4, 100.0)
    biased = replace(scenario, noise=replace(scenario.noise, ahrs_gyro_bias_rad_per_s=0.01))
    root = write_dataset(simulate_records(biased), tmp_path / "biased")
    config = tmp_path / "gw.toml"
    config.write_text("[noise]\nahrs_bias_walk_deg_per_sqrt_s = 0.15\n")
    args = ["run", str(root), "--backend", "isam2", "--config", str(config), "--quiet"]
    assert main([*args, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "the gyro reads +0.5" in err and "no gyro-bias state" in err
    assert not (tmp_path / "o").exists()
    from sonarslam.slam.run.presets import check_combination

    unbiased = open_dataset(harbour, config_override=config)
    assert unbiased.config.yaw_rate_source == "gyro"
    check_combination(unbiased, "isam2")  # nothing to refuse


def test_dead_reckoning_names_the_settings_it_ignores(harbour, tmp_path, capsys):
    from sonarslam.slam.run.sources import DR_IGNORES

    assert main(["info", str(harbour)]) == 0
    assert "[motion] yaw_rate_source" in capsys.readouterr().out
    assert (
        main(["run", str(harbour), "--backend", "dr", "--out", str(tmp_path / "o"), "--quiet"]) == 0
    )
    used = (tmp_path / "o" / "config_used.toml").read_text()
    assert all(f"# ignored by dead reckoning: {k}" in used for k in DR_IGNORES)


def test_the_closed_loops_say_which_ahrs_sigma_they_use(harbour, tmp_path, capsys):
    """[noise] ahrs_sigma_deg moves dead reckoning's covariance and only the closed loops'
    start pose (their AHRS model is white noise plus a bias): info and a closed loop's
    config_used.toml say so (a review found it 'without effect' in ekf and isam2, unsaid)."""
    from sonarslam.slam.run.sources import CLOSED_LOOP_START_ONLY

    assert main(["info", str(harbour)]) == 0
    out = capsys.readouterr().out
    assert "[noise] ahrs_sigma_deg for the start pose's heading only" in out
    assert "ahrs_white_sigma_deg" in out and "ahrs_bias_sigma_deg" in out
    assert (
        main(["run", str(harbour), "--backend", "ekf", "--out", str(tmp_path / "e"), "--quiet"])
        == 0
    )
    used = (tmp_path / "e" / "config_used.toml").read_text()
    assert all(
        f"): {k}" in used and "# the start pose's only" in used for k in CLOSED_LOOP_START_ONLY
    )


# -- the docs' rules, read from the one place they are made --------------------------------


def test_the_docs_state_the_number_grammar_of_the_code():
    """docs/bad-input.md quotes datasets.logfile.NUMBER; the code accepts exactly it."""
    assert f"`{NUMBER}`" in BAD_INPUT.read_text(encoding="utf-8")
    for text in ("5.", ".5", "+.5", "-1e3", "2.5E-02"):
        assert re.fullmatch(NUMBER, text)
    for text in (".", "+", "1e", "e3", "1_0", "0x1", "nan", "inf"):
        assert not re.fullmatch(NUMBER, text)


@pytest.mark.parametrize("head", [b"\xef\xbb\xbf", b"VERSION 0.7\n# \xc3\xa9\n"])
def test_a_pcd_header_that_is_not_ascii_is_refused(tmp_path, head):
    pcd = tmp_path / "k.pcd"
    body = b"VERSION 0.7\nFIELDS x y z\nPOINTS 1\nDATA ascii\n1.0 2.0 0.0\n"
    pcd.write_bytes(head + body if head.startswith(b"\xef") else head + body[12:])
    with pytest.raises(DataError, match=r"k\.pcd:[12]: byte 0x(EF|C3) at column \d+ is not ASCII"):
        read_pcd(pcd)


def test_the_row_rules_are_the_docs(tmp_path):
    """A log row with the wrong count of fields is skipped and counted; the keyframe CSV (an
    index of scans) and a PCD (a declared count of points) refuse it, as docs/bad-input.md
    says."""
    text = BAD_INPUT.read_text(encoding="utf-8")
    assert "skipped with one warning per file counting them" in text
    assert "a keyframe-CSV or PCD row with the wrong number of fields is a" in text
    log = tmp_path / "a_DVL.log"
    log.write_text("1.0 2.0\n2.0\n3.0 4.0\n")
    with pytest.warns(DataWarning, match=r"skipped 1 row\(s\) without 2 columns \(lines 2\)"):
        assert read_table(log).data.shape == (2, 2)
    csv = tmp_path / "k.csv"
    csv.write_text("keyFrame,keyFrameBeginning,keyFrameEnd\n1,2.0,3.0\n2,4.0\n")
    with pytest.raises(DataError, match=r"k\.csv:3: expected 3 fields, got 2"):
        read_keyframe_times(csv)


def test_a_table_read_in_blocks_is_the_table_read_whole(tmp_path):
    """The streaming reader: same rows, line numbers, warning and errors at any block size."""
    rng = np.random.default_rng(0)
    rows = [" ".join(f"{v:.3f}" for v in [t, *rng.uniform(0, 9, 3)]) for t in range(200)]
    rows[17] = "17.0 1.0"  # a short row, skipped
    path = tmp_path / "x.log"
    path.write_text("% header\r\n" + "\r\n".join(rows) + "\r\n3")  # a cut last line
    with pytest.warns(DataWarning) as whole_w:
        whole = read_table(path)
    for block in (7, 64, 1000, 1 << 20):
        with pytest.warns(DataWarning) as part_w:
            parts = list(iter_tables(path, block_bytes=block))
        assert np.array_equal(np.vstack([p.data for p in parts]), whole.data)
        got = np.concatenate([p.line_numbers for p in parts])
        assert np.array_equal(got, whole.line_numbers)
        assert [str(w.message) for w in part_w] == [str(w.message) for w in whole_w]
    path.write_text("\n".join(rows[:100] + ["5.0 1 2 3"] + rows[101:]) + "\n")
    for block in (64, 1 << 20):
        with pytest.raises(DataError, match=r"x\.log:101: time goes backwards"):
            list(iter_tables(path, block_bytes=block))


# -- thin overlaps, one-row logs, calibration on too few beams -----------------------------


def test_a_thin_overlap_is_warned_and_a_one_row_log_has_its_own_message(harbour, tmp_path):
    folder = shutil.copytree(harbour, tmp_path / "h")
    mti = _log(folder, "MTi")
    edit_log_rows(mti, lambda t, f: [f] if t < 5.0 else [])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        open_dataset(folder)
    msgs = [str(w.message) for w in caught if issubclass(w.category, DataWarning)]
    assert any(re.search(r"the DVL and AHRS overlap for [45]\.\d s", m) for m in msgs), msgs
    dvl = _log(folder, "DVL")
    first = {"done": False}

    def one_row(t: float, f: list[str]) -> list[list[str]]:
        keep = not first["done"]
        first["done"] = True
        return [f] if keep else []

    edit_log_rows(dvl, one_row)
    with pytest.raises(DataError, match=r"_DVL\.log: the DVL log has 1 row\(s\) spanning 0\.000 s"):
        open_dataset(folder)


def test_calibrate_refuses_too_few_beams(harbour, tmp_path, capsys):
    folder = shutil.copytree(harbour, tmp_path / "h")
    edit_log_rows(_log(folder, "MTi"), lambda t, f: [f] if t < 5.0 else [])
    assert main(["calibrate", str(folder), "--poses", "dr"]) == 1
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "too few to calibrate the sonar yaw: it needs 10 turns of the head" in err


# -- the keyframe cache ------------------------------------------------------------------


def _keyframes(folder: Path, points: list[tuple[int, int]]) -> np.ndarray:
    """One keyframe of a 1.8 deg, 500 x 0.1 m head: its CSV, its PCD with the points
    ``(angle index, bin)``, and the beam times (returned)."""
    folder.mkdir(parents=True, exist_ok=True)
    t = 1.7e9 + 0.1 * np.arange(250)
    (folder / "keyFrameTimeStamps.csv").write_text(
        f"keyFrame,keyFrameBeginning,keyFrameEnd\n1,{t[10]:.4f},{t[209]:.4f}\n"
    )
    rows = []
    for j, b in points:
        a, r = np.deg2rad(1.8 * j), 0.1 * (b + 1)
        rows.append(f"{r * np.cos(a):.6f} {r * np.sin(a):.6f} 0.0")
    header = f"VERSION 0.7\nFIELDS x y z\nPOINTS {len(rows)}\nDATA ascii\n"
    (folder / "pclKeyFrame1.pcd").write_text(header + "\n".join(rows) + "\n")
    return t


def test_the_keyframe_cache_is_used_and_rebuilt_when_a_source_changes(tmp_path, monkeypatch):
    from sonarslam.datasets.cache import cache_file
    from sonarslam.datasets.keyframes import read_keyframes
    from sonarslam.sonar.beam import SonarHead

    monkeypatch.delenv("SONARSLAM_CACHE", raising=False)
    head = SonarHead(n_bins=500, bin_size_m=0.1, step_rad=np.deg2rad(1.8))
    folder = tmp_path / "kf"
    t = _keyframes(folder, [(3, 40), (100, 7)])
    first = read_keyframes(folder, t, head)
    cached = cache_file(folder, "keyframes")
    assert cached == folder / ".sonarslam-keyframes.npz" and cached.is_file()
    again = read_keyframes(folder, t, head)
    assert np.array_equal(again.intensities, first.intensities)
    assert np.array_equal(again.t_s, first.t_s) and np.array_equal(
        again.transducer_angle_rad, first.transducer_angle_rad
    )
    assert int((first.intensities == 255).sum()) == 2
    _keyframes(folder, [(3, 40), (100, 7), (150, 9)])  # one point more: rebuilt
    assert int((read_keyframes(folder, t, head).intensities == 255).sum()) == 3
    cached.write_bytes(b"not a cache")  # a damaged cache is parsed again, never trusted
    assert int((read_keyframes(folder, t, head).intensities == 255).sum()) == 3
    other = tmp_path / "cache"
    monkeypatch.setenv("SONARSLAM_CACHE", str(other))
    ro = tmp_path / "ro"
    _keyframes(ro, [(1, 1)])
    ro.chmod(0o555)  # the shared datasets' mode: not written, even by root
    try:
        read_keyframes(ro, t, head)
        assert not (ro / ".sonarslam-keyframes.npz").exists()
        assert [p.parent for p in other.glob("keyframes-*.npz")] == [other]
    finally:
        ro.chmod(0o755)
    monkeypatch.setenv("SONARSLAM_CACHE", "off")
    cached.unlink()
    read_keyframes(folder, t, head)
    assert not cached.exists()


def test_a_back_ends_write_error_names_the_folder(tmp_path):
    from sonarslam.slam.io.files import write_files_into

    def full(folder: Path) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    with pytest.raises(OSError) as info:
        write_files_into(tmp_path, full)
    assert info.value.filename == str(tmp_path) and list(tmp_path.iterdir()) == []
