"""Fuzzing the readers, the configuration and the dataset opener (``tests/fuzzing.py``): seeded
mutations of small real slices, hypothesis-generated logs, TOML files and ``--set`` values.
The long mode is ``benchmarks/fuzz_readers.py --cases 20000``."""

from __future__ import annotations

import itertools
import json
import math
import os
import re
import tomllib
import zlib

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sonarslam.datasets.config import _SCHEMA as TOML_SCHEMA  # what each key of the file sets
from sonarslam.datasets.config import load_dataset_config
from sonarslam.datasets.errors import DataError
from sonarslam.datasets.logfile import NUMBER, read_table
from sonarslam.settings import SettingError
from sonarslam.slam.run.presets import parse_settings
from tests.fuzz_inputs import Mutation, build_seeds, ref_lines
from tests.fuzz_oracles import check_toml, match_rows
from tests.fuzzing import TARGETS, check_setting, fuzz, run_case, summarise

#: Hypothesis examples per property (``FUZZ_EXAMPLES=3000`` for a long run).
FUZZ = settings(
    max_examples=int(os.environ.get("FUZZ_EXAMPLES", "150")),
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)


@pytest.fixture(scope="module")
def seeds(tmp_path_factory):
    return build_seeds(tmp_path_factory.mktemp("seeds"))


def test_number_grammar_is_numpy_parsing_on_its_alphabet():
    """The tokenizer's fast path lets numpy convert tokens of ``0-9 e E + - .``: on that
    alphabet numpy must accept exactly the grammar NUMBER (every token to 6 characters)."""
    grammar = re.compile(NUMBER)
    for n in range(1, 7):
        for chars in itertools.product("01eE+-.", repeat=n):
            token = "".join(chars)
            try:
                np.array([token.encode()], dtype=np.float64)
                numpy_ok = True
            except ValueError:
                numpy_ok = False
            assert numpy_ok == (grammar.fullmatch(token) is not None), token


@pytest.mark.parametrize("target", sorted(TARGETS))
def test_seeded_mutations_give_a_data_error_or_right_values(seeds, tmp_path, target):
    outcomes = fuzz(seeds, 60, tmp_path, seed=zlib.crc32(target.encode()), targets=[target])
    row = summarise(outcomes)[0]
    bad = [(o.status, o.mutation, o.message, o.problems) for o in outcomes if o.problems]
    assert row["foreign"] == 0 and row["hang"] == 0 and not bad, bad[:3]
    assert row["data_error"] > 0 and row["accepted"] > 0  # the mutations bite, and not all


@pytest.mark.parametrize("kind", ["directory", "fifo", "dev_zero", "symlink_loop", "empty"])
@pytest.mark.parametrize(
    "target",
    [
        "read_dvl",
        "read_pcd_xy",
        "load_dataset_config",
        "read_truth",
        "open_bag ros1",
        "open_bag mcap",
        "open_bag sqlite3",
        "read_ping360_log",
    ],
)
def test_special_files_are_refused_before_reading(seeds, tmp_path, target, kind):
    seed = seeds[TARGETS[target].seed]
    m = Mutation("special", kind, None, seed.primary, kind)
    out = run_case(target, seed, m, tmp_path, limit_s=5.0)
    if kind == "empty" and target == "load_dataset_config":  # an empty TOML file sets nothing
        assert out.status == "accepted" and not out.problems
        return
    assert out.status == "data_error" and not out.problems, (out.message, out.problems)
    assert seed.primary.split("/")[-1] in out.message


def test_an_opened_dataset_keeps_the_gates_promises_under_mutation(seeds, tmp_path):
    outcomes = fuzz(seeds, 120, tmp_path, seed=7, targets=["open_dataset"])
    bad = [
        (o.mutation, o.message, o.problems)
        for o in outcomes
        if o.problems or o.status in ("foreign", "hang")
    ]
    assert not bad, bad[:3]


# --- hypothesis: logs, TOML, --set -------------------------------------------------------------

_SEPARATORS = [" ", "\t", " \t ", "\x0b", "\xa0", "\x1f", ","]
_BREAKS = ["\n", "\r\n", "\r", "\x0b", "\x0c", "\x1c", "\x85"]
_TOKENS = st.one_of(
    st.floats(allow_nan=False, allow_infinity=False, width=64).map(repr),
    st.integers(-(10**30), 10**30).map(str),
    st.sampled_from(["nan", "inf", "1e999", "1_0", "0x10", "1.", ".5", "1e", "-", "+1", "%"]),
    st.text(alphabet="0123456789.eE+- x\u0661\uff11", max_size=6),
)


@st.composite
def logs(draw):
    lines = []
    for _ in range(draw(st.integers(1, 8))):
        tokens = draw(st.lists(_TOKENS, min_size=1, max_size=4))
        seps = draw(
            st.lists(st.sampled_from(_SEPARATORS), min_size=len(tokens), max_size=len(tokens))
        )
        lines.append("".join(t + s for t, s in zip(tokens, seps, strict=True))[:-1])
    breaks = draw(st.lists(st.sampled_from(_BREAKS), min_size=len(lines), max_size=len(lines)))
    text = "".join(line + b for line, b in zip(lines, breaks, strict=True))
    if draw(st.booleans()):
        text = text.rstrip("\r\n")  # no line end at the last line
    return text.encode("utf-8")


@FUZZ
@given(data=logs())
def test_read_table_is_the_reference_tokenizer_or_names_the_line(tmp_path, data):
    path = tmp_path / "x.log"
    path.write_bytes(data)
    try:
        table = read_table(path, n_columns=3, time_column=None)
    except DataError as exc:
        n_lines = len(ref_lines(data)[0])
        assert exc.path == path and str(path) in str(exc)
        assert exc.line is None or 1 <= exc.line <= n_lines
        return
    assert np.all(np.isfinite(table.data))
    m = Mutation("none", "", data, "x.log")
    assert not match_rows(table.data, data, data, m, 3, (0, 1, 2), lambda e: e)


_TOML_TABLES = [*TOML_SCHEMA, "mounting.x", "extra"]
_TOML_VALUES = st.one_of(
    st.integers(-(10**20), 10**20),
    st.floats(allow_nan=True, allow_infinity=True),
    st.booleans(),
    st.text(alphabet=st.characters(blacklist_categories=("Cs",)), max_size=5),
    st.lists(st.floats(-10, 10), max_size=3),
)


def _toml_value(v: object) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return (
            "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
        )
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, str):
        return json.dumps(v)
    return str(v)


@st.composite
def toml_files(draw):
    out = []
    if draw(st.integers(0, 5)) == 0:  # a table given as a value
        out.append(
            f"{draw(st.sampled_from(['sonar', 'noise', 'mounting']))} = {_toml_value(draw(_TOML_VALUES))}"
        )
    for table in draw(st.lists(st.sampled_from(_TOML_TABLES), max_size=3, unique=True)):
        keys = list(TOML_SCHEMA.get(table, {})) + ["unknown_key"]
        out.append(f"[{table}]")
        for key in draw(st.lists(st.sampled_from(keys), max_size=3, unique=True)):
            out.append(f"{key} = {_toml_value(draw(_TOML_VALUES))}")
    return "\n".join(out) + "\n"


@FUZZ
@given(text=toml_files())
def test_toml_values_are_taken_exactly_or_named(tmp_path, text):
    path = tmp_path / "sonarslam.toml"
    path.write_text(text, encoding="utf-8")
    try:
        config = load_dataset_config(path)
    except DataError as exc:
        assert exc.path == path and str(path) in str(exc)
        return
    tomllib.loads(text)  # what was accepted is TOML
    m = Mutation("none", "", text.encode(), "sonarslam.toml")
    assert not check_toml(config, text.encode(), b"", m, tmp_path)


_FIELDS = st.sampled_from(
    [
        "extractor.min_votes",
        "extractor.rho_res_m",
        "extractor.max_range_m",
        "extractor.vote_model",
        "extractor.requery_poses",
        "ekf.association",
        "ekf.extent_margin_m",
        "isam2.robust",
        "isam2.max_candidates",
        "ekf.association.gate_probability",
        "extractor.nope",
        "nope.x",
    ]
)


@FUZZ
@given(
    name=_FIELDS,
    value=st.one_of(_TOKENS, st.sampled_from(["true", "none", "nn", "cauchy", "12", "25.0"])),
)
def test_set_values_fit_their_field_or_are_a_usage_error(name, value):
    out = check_setting(f"{name}={value}")
    assert out.status in ("accepted", "data_error") and not out.problems, (
        out.message,
        out.problems,
    )


def test_set_names_the_key_and_the_reason():
    for spec, reason in (
        ("extractor.min_votes=1.5", "whole number"),
        ("extractor.rho_res_m=0", r"\[0.01, 10\]"),
        ("extractor.max_range_m=nan", "must be a finite number"),
        ("ekf.ahrs_period_s=abc", "must be a finite number"),
        ("isam2.robust=2", "must be a string"),
    ):
        out = check_setting(spec)
        assert out.status == "data_error" and re.search(reason, out.message), (spec, out.message)
        assert spec.split("=")[0] in out.message
    with pytest.raises(SettingError, match="SCOPE.FIELD=VALUE"):
        parse_settings(["min_votes"])


def test_fuzzing_is_seeded(seeds, tmp_path):
    a = fuzz(seeds, 26, tmp_path, seed=3)
    b = fuzz(seeds, 26, tmp_path, seed=3)
    assert [(o.target, o.status, o.mutation) for o in a] == [
        (o.target, o.status, o.mutation) for o in b
    ]


def test_bad_bags_are_one_error_or_a_counted_warning(seeds, tmp_path):
    """Issue 30's bad bags (tests/fuzz_inputs.bad_bags): a DataError naming the bag (and the
    topic and the message's index where one message is at fault), or a read with a counted
    warning; never another exception."""
    import warnings

    from sonarslam.datasets.errors import DataWarning
    from sonarslam.datasets.rosbag import open_bag
    from tests.fuzz_inputs import bad_bags

    cases = bad_bags(tmp_path, seeds["bag_ros1"])
    assert len(cases) == 9
    for case in cases:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            if case.expect == "error":
                with pytest.raises(DataError) as info:
                    open_bag(case.path, topics_file=case.topics)
                message = str(info.value)
                assert str(info.value.path) in message, case.name
                for pattern in case.says:
                    assert re.search(pattern, message), (case.name, pattern, message)
                continue
            d = open_bag(case.path, topics_file=case.topics)
        said = " ".join(str(w.message) for w in caught if issubclass(w.category, DataWarning))
        assert not [w for w in caught if not issubclass(w.category, DataWarning)], case.name
        if case.expect == "warning":
            assert d.report.counts[case.count] == 1, case.name
            for pattern in case.says:
                assert re.search(pattern, said), (case.name, pattern, said)
        assert len(d.beams) > 0 and np.all(np.diff(d.attitude.t) > 0), case.name
