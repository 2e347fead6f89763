"""Fault specification parser: every kind accepted with its defaults, every mistake one clear
error naming the entry, and fuzzing (random text, structured garbage) raising nothing else."""

from __future__ import annotations

import math

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ins_gnss_ros.faults import KINDS, FaultSpecError, load_fault_spec, parse_fault_spec

EVERY_KIND = """
seed: 42
faults:
  - {kind: drop, topic: imu/data_raw, start: 1, duration: 2, probability: 0.5}
  - {kind: delay, topic: gnss/fix, start: 0, delay_s: 0.2}
  - {kind: duplicate, topic: gnss/fix, start: 3, duration: 1}
  - {kind: reorder, topic: imu/data_raw, start: 5, duration: 1, window: 4}
  - {kind: freeze, topic: imu/mag_raw, start: 6, duration: 2}
  - {kind: step, topic: gnss/fix, start: 7, field: latitude, value: 1.0e-4}
  - {kind: ramp, topic: imu/data_raw, start: 8, field: angular_velocity.z, rate: 0.001}
  - {kind: nan, topic: imu/data_raw, start: 9, duration: 0.1, field: linear_acceleration.x}
  - {kind: inf, topic: gnss/observations, start: 9, duration: 1, field: pseudorange}
  - {kind: absurd, topic: gnss/vel, start: 9, duration: 1, field: twist.twist.linear.x}
  - {kind: clock_jump, topic: 'imu/*', start: 10, offset_s: -1.5}
  - {kind: clock_drift, topic: imu/data_raw, start: 0, ppm: 200}
  - {kind: loop, topic: '*', start: 20, duration: 10}
  - {kind: gnss_outage, start: 30, duration: 60, name: long outage}
  - {kind: satellite_loss, start: 100, duration: 30, ramp_s: 20, remaining: 2}
  - {kind: position_jump, start: 140, duration: 10, north_m: 500, ramp_s: 5}
  - {kind: magnetic_disturbance, start: 150, duration: 5, field_t: [1.0e-5, 0, 0]}
  - {kind: cycle_slip, start: 160, cycles: 1, fraction: 0.3}
"""


def test_every_kind_parses_with_defaults_and_windows():
    spec = load_fault_spec(EVERY_KIND, text=True)
    assert spec.seed == 42
    assert [f.kind for f in spec.faults] == list(KINDS)
    by_kind = {f.kind: f for f in spec.faults}
    assert by_kind["drop"].topic == "/imu/data_raw"
    assert (by_kind["drop"].start_s, by_kind["drop"].end_s) == (1.0, 3.0)
    assert by_kind["delay"].end_s == math.inf
    assert by_kind["duplicate"].params == {"copies": 1, "probability": 1.0}
    assert by_kind["gnss_outage"].topic == "/gnss/*"
    assert by_kind["gnss_outage"].name == "long outage"
    assert by_kind["cycle_slip"].topic == "/gnss/observations"
    assert by_kind["magnetic_disturbance"].topic == "/imu/mag_raw"
    assert by_kind["step"].name == "5:step"
    assert by_kind["gnss_outage"].matches("/gnss/heading")
    assert not by_kind["loop"].matches("/truth/state")


def test_loop_without_duration_replays_everything_before_it():
    (f,) = load_fault_spec("faults: [{kind: loop, topic: '*', start: 12}]", text=True).faults
    assert (f.start_s, f.end_s) == (12.0, 24.0)


@pytest.mark.parametrize("entry, message", [
    ("{kind: drop}", r"faults\[0\] \(drop\): missing 'topic'"),
    ("{kind: drop, topic: a}", r"faults\[0\] \(drop\): 'start' must be a number"),
    ("{kind: dorp, topic: a, start: 1}", r"faults\[0\]: unknown kind 'dorp'"),
    ("{topic: a, start: 1}", r"faults\[0\]: unknown kind None"),
    ("{kind: drop, topic: a, start: -1}", r"'start' must be a number of seconds in \[0"),
    ("{kind: drop, topic: a, start: 1, duration: -2}", r"\(drop\): 'duration' must be"),
    ("{kind: drop, topic: a, start: 1, duration: 0}", r"\(drop\): 'duration' must be"),
    ("{kind: drop, topic: a, start: true}", r"'start' must be a number"),
    ("{kind: drop, topic: a, start: 1, probability: 2}", r"'probability' must be a number, in"),
    ("{kind: drop, topic: a, start: 1, extra: 1}", r"\(drop\): unknown key 'extra'"),
    ("{kind: delay, topic: a, start: 1}", r"\(delay\): missing 'delay_s'"),
    ("{kind: step, topic: a, start: 1, field: x, value: '1.0e9'}", r"write it without quotes"),
    ("{kind: step, topic: a, start: 1, field: 'a..b', value: 1}", r"dotted field path"),
    ("{kind: step, topic: a, start: 1, field: x, value: .inf}", r"faults\[0\]\.value"),
    ("{kind: duplicate, topic: a, start: 1, copies: 1.5}", r"'copies' must be an integer"),
    ("{kind: clock_jump, topic: a, start: 1, offset_s: 0}", r"'offset_s' must be a number, non"),
    ("{kind: loop, topic: a, start: 5, duration: 6}", r"\(loop\): 'duration' \(6 s\)"),
    ("{kind: loop, topic: a, start: 0}", r"\(loop\): 'start' must be > 0"),
    ("{kind: cycle_slip, start: 1, cycles: 0}", r"'cycles' must be an integer, non-zero"),
    ("{kind: magnetic_disturbance, start: 1, field_t: [1, 2, x]}", r"'field_t' must be a list"),
    ("{kind: inf, topic: a, start: 1, field: x, negative: 1}", r"'negative' must be true/false"),
    ("[1, 2]", r"faults\[0\]: an entry is a mapping"),
])
def test_bad_entries_name_the_entry(entry, message):
    with pytest.raises(FaultSpecError, match=message) as err:
        load_fault_spec(f"faults:\n  - {entry}", text=True)
    assert "\n" not in str(err.value) and str(err.value).startswith("<text>:")


@pytest.mark.parametrize("text, message", [
    ("faults: {}", "'faults' must be a list"),
    ("seed: -1\nfaults: []", "'seed' must be a non-negative integer"),
    ("fault: []", "unknown top-level key 'fault'"),
    ("- 1", "must be a mapping"),
    ("faults: [", "malformed YAML"),
])
def test_bad_documents(text, message):
    with pytest.raises(FaultSpecError, match=message):
        load_fault_spec(text, text=True)


def test_file_errors_name_the_file(tmp_path):
    with pytest.raises(FaultSpecError, match="cannot read"):
        load_fault_spec(tmp_path / "missing.yaml")
    big = tmp_path / "big.yaml"
    big.write_text("faults: []\n" + "#" * (2 << 20))
    with pytest.raises(FaultSpecError, match=r"big\.yaml: larger than"):
        load_fault_spec(big)
    bad = tmp_path / "bad.yaml"
    bad.write_text("faults:\n  - {kind: step, topic: a, start: 1, field: x}\n")
    with pytest.raises(FaultSpecError, match=r"bad\.yaml: faults\[0\] \(step\): missing 'value'"):
        load_fault_spec(bad)


# -- fuzzing ------------------------------------------------------------------------------------
FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])

scalars = st.one_of(st.none(), st.booleans(), st.integers(-10**20, 10**20),
                    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=12),
                    st.sampled_from(list(KINDS)))
keys = st.sampled_from(["kind", "topic", "start", "duration", "name", "field", "value", "rate",
                        "probability", "copies", "window", "delay_s", "offset_s", "remaining",
                        "ramp_s", "north_m", "east_m", "up_m", "field_t", "cycles", "fraction",
                        "negative", "bogus"])
values = st.recursive(scalars, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=5), inner, max_size=4)),
    max_leaves=12)
entries = st.one_of(values, st.dictionaries(keys, values, max_size=8),
                    st.fixed_dictionaries({"kind": st.sampled_from(list(KINDS)),
                                           "start": st.floats(-1, 100) | st.integers(-2, 100)},
                                          optional={k: values for k in ("topic", "duration",
                                                                        "field", "value")}))
documents = st.one_of(values, st.fixed_dictionaries(
    {"faults": st.lists(entries, max_size=4)}, optional={"seed": values}))


@FUZZ
@given(documents)
def test_fuzz_structured_garbage_raises_only_spec_errors(doc):
    try:
        parse_fault_spec(doc)
    except FaultSpecError as err:
        assert "\n" not in str(err)


@FUZZ
@given(documents)
def test_fuzz_yaml_round_trip_raises_only_spec_errors(doc):
    try:
        text = yaml.safe_dump(doc)
    except (yaml.YAMLError, ValueError):
        return
    try:
        load_fault_spec(text, text=True)
    except FaultSpecError as err:
        assert "\n" not in str(err)


@FUZZ
@given(st.text(max_size=300) | st.binary(max_size=300).map(lambda b: b.decode("latin-1")))
def test_fuzz_random_text_raises_only_spec_errors(text):
    try:
        load_fault_spec(text, text=True)
    except FaultSpecError as err:
        assert "\n" not in str(err)
