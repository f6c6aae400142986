"""One validation mechanism for every setting a file or the command line can write: each
number of a configuration class carries its range and each word its choices in the field's
metadata (:func:`sonarslam.settings.bounded`, :func:`sonarslam.settings.one_of`), checked by
:func:`sonarslam.settings.check_fields`; an error names the setting (and the file and line
where a TOML wrote it, tests/test_readers.py)."""

from __future__ import annotations

import ast
import dataclasses
import math
import typing
from pathlib import Path

import pytest

from sonarslam.datasets.config import DatasetConfig, NoiseConfig, load_dataset_config
from sonarslam.datasets.errors import DataError
from sonarslam.features.config import ExtractorConfig
from sonarslam.features.scans import ScanConfig
from sonarslam.settings import SettingError, bounded, check_fields, field_types, replace_checked
from sonarslam.slam.backends.ekf import EkfConfig
from sonarslam.slam.backends.registry import BACKENDS
from sonarslam.slam.eval.health import HealthConfig
from sonarslam.slam.model.noise import MotionNoise
from sonarslam.slam.run.presets import apply_overrides, backend_config

ROOT = Path(__file__).resolve().parent.parent

#: Free-form words, no list of choices: where a mounting's numbers come from; the back ends'
#: ``constraints`` and ``learn_noise``, comma lists their class parses and checks
#: (BackendConfig.__post_init__).
FREE_TEXT = {
    ("Mounting", "source"),
    ("EkfConfig", "constraints"),
    ("GraphConfig", "constraints"),
    ("EkfConfig", "learn_noise"),
    ("GraphConfig", "learn_noise"),
}


def _config_classes() -> list[type]:
    """Every dataclass a setting reaches: the dataset's file, the extractor, the scan matcher,
    the back ends and the health monitor, with their nested tables."""
    roots: list[type] = [DatasetConfig, ExtractorConfig, ScanConfig, HealthConfig]
    roots += [spec.config_type for spec in BACKENDS.values()]
    seen: list[type] = []

    def walk(cls: type) -> None:
        if cls in seen:
            return
        seen.append(cls)
        for annotation in field_types(cls).values():
            if dataclasses.is_dataclass(annotation):
                walk(annotation)  # type: ignore[arg-type]

    for root in roots:
        walk(root)
    return seen


CLASSES = _config_classes()


def _base_type(annotation: typing.Any) -> typing.Any:
    args = [a for a in typing.get_args(annotation) if a is not type(None)]
    base = args[0] if typing.get_origin(annotation) is not tuple and args else annotation
    if typing.get_origin(base) is tuple:
        base = typing.get_args(base)[0]
    return base


@pytest.mark.parametrize("cls", CLASSES, ids=[c.__name__ for c in CLASSES])
def test_every_number_has_a_range_and_every_word_its_choices(cls: type) -> None:
    assert len(CLASSES) >= 10
    fields = {f.name: f for f in dataclasses.fields(cls)}
    for name, annotation in field_types(cls).items():
        meta = fields[name].metadata
        base = _base_type(annotation)
        if base in (int, float):
            assert "range" in meta or "choices" in meta, f"{cls.__name__}.{name} has no range"
        elif base is str and (cls.__name__, name) not in FREE_TEXT:
            assert "choices" in meta, f"{cls.__name__}.{name} has no choices"


@pytest.mark.parametrize("cls", CLASSES, ids=[c.__name__ for c in CLASSES])
def test_every_range_is_enforced_by_name(cls: type) -> None:
    """Just outside each closed range (or on an open end) the class refuses the value, naming
    the field; its default is inside."""
    obj = cls()
    for f in dataclasses.fields(cls):
        r = f.metadata.get("range")
        if r is None:
            continue
        default = getattr(obj, f.name)
        for v in default if isinstance(default, tuple) else (default,):
            assert v is None or r.low <= v <= r.high, f"{cls.__name__}.{f.name} default {v}"
        for bad, open_end in ((r.low, r.low_open), (r.high, r.high_open)):
            if not math.isfinite(bad):
                continue
            if not open_end:
                bad = bad - 1.0 if bad == r.low else bad + 1.0
            value = (bad, bad) if isinstance(default, tuple) else bad
            with pytest.raises(SettingError, match=rf"^{f.name}: must be in"):
                replace_checked(obj, {f.name: value})


def test_check_fields_names_the_field_and_checks_choices_and_tuples() -> None:
    @dataclasses.dataclass(frozen=True)
    class Demo:
        rate_deg_per_s: float = bounded(1.0, 0.0, 10.0, low_open=True)
        pair_m: tuple[float, float] = bounded((0.0, 0.0), -1.0, 1.0)

        def __post_init__(self) -> None:
            check_fields(self)

    Demo()
    with pytest.raises(ValueError, match=r"rate_deg_per_s must be in \(0, 10\], got 0.0"):
        Demo(rate_deg_per_s=0.0)
    with pytest.raises(ValueError, match=r"pair_m must be in \[-1, 1\], got 2.0"):
        Demo(pair_m=(0.0, 2.0))
    with pytest.raises(SettingError, match=r"^extractor.vote_model: must be one of 'arc', "):
        replace_checked(ExtractorConfig(), {"vote_model": "votes"}, prefix="extractor.")


def test_no_module_checks_a_range_its_own_way() -> None:
    """The range checks of the old styles are gone: no ``check_within`` outside
    sonarslam/settings.py."""
    for folder in ("sonar", "features", "datasets", "slam"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"))
            for node in ast.walk(tree):
                if isinstance(node, ast.Name):
                    assert node.id != "check_within", f"{path}:{node.lineno}"


def test_a_renamed_key_is_an_error_naming_the_new_one(tmp_path: Path) -> None:
    """One spelling per unit (deg/s: ``_deg_per_s``, rad/s: ``_rad_per_s``) and one home per
    noise value (the dataset's ``[noise]``): the old names are errors that say the new one."""
    path = tmp_path / "sonarslam.toml"
    path.write_text("[gates]\nmin_gap_s = 2.0\nahrs_max_rate_dps = 300.0\n", encoding="utf-8")
    with pytest.raises(DataError, match=r"sonarslam.toml:3: .*renamed ahrs_max_rate_deg_per_s"):
        load_dataset_config(path)
    path.write_text("[gates]\nahrs_max_rate_deg_per_s = 300.0\n", encoding="utf-8")
    assert load_dataset_config(path).gates.ahrs_max_rate_deg_per_s == 300.0
    with pytest.raises(SettingError, match=r"^ekf.gyro_sigma_radps: .*ekf.noise.gyro_sigma_rad"):
        apply_overrides(EkfConfig(), {"gyro_sigma_radps": 0.01}, prefix="ekf.")
    cfg = apply_overrides(EkfConfig(), {"noise.gyro_sigma_rad_per_s": 0.01}, prefix="ekf.")
    assert cfg.noise.gyro_sigma_rad_per_s == 0.01


def test_the_back_ends_noise_is_the_dataset_s() -> None:
    """No noise value of the back ends' own: the runner hands them the dataset's ``[noise]``
    whole, and the motion model's comes from the same table."""
    noise = NoiseConfig(ahrs_white_sigma_deg=0.7, gyro_sigma_rad_per_s=0.002)
    for name in BACKENDS:
        assert backend_config(name, noise=noise).noise == noise
        assert backend_config(name).noise == NoiseConfig()
    motion = MotionNoise.from_config(noise)
    assert motion.ahrs_sigma_rad == pytest.approx(math.radians(noise.ahrs_sigma_deg))
    assert motion.gap_sigma_mps == noise.dvl_gap_sigma_mps
    names = {f.name for f in dataclasses.fields(EkfConfig)}
    assert not names & {f.name for f in dataclasses.fields(NoiseConfig)}


def test_the_noise_keys_a_back_end_lists_are_those_it_reads() -> None:
    """``BACKEND_NOISE_KEYS`` (what ``info`` lists and ``--set`` takes as ``<backend>.noise.*``)
    is the set of ``[noise]`` keys the back ends' code reads from their configuration."""
    import re

    from sonarslam.slam.backends.base import BACKEND_NOISE_KEYS

    fields = {f.name for f in dataclasses.fields(NoiseConfig)}
    read: set[str] = set()
    for path in (ROOT / "slam" / "backends").rglob("*.py"):
        read |= set(re.findall(r"config\.noise\.(\w+)", path.read_text())) & fields
    assert read == set(BACKEND_NOISE_KEYS)
    with pytest.raises(SettingError, match=r"^ekf\.noise\.dvl_sigma_mps: the back end does not"):
        backend_config("ekf", {"noise.dvl_sigma_mps": 0.1})


def test_a_key_in_degrees_out_of_range_is_said_in_degrees(tmp_path: Path) -> None:
    """The fields are in radians; a ``_deg`` key's range is said in degrees, with the value as
    written."""
    for text, said in [
        ("[sonar]\nstep_deg = 0.0314\n", "[sonar] step_deg: must be in [0.1, 180) deg, got 0.0314"),
        ("[mounting.dvl]\nyaw_deg = 400\n", "[mounting.dvl] yaw_deg: must be in [-360, 360] deg"),
    ]:
        path = tmp_path / "s.toml"
        path.write_text(text)
        with pytest.raises(DataError) as e:
            load_dataset_config(path)
        assert str(e.value).startswith(f"{path}:2: {said}")
