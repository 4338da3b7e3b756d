"""hypothesis fuzzing of the scenario loader and the CSV reader: any input gives a result or a typed,
one-line input error naming the file, never another exception, and never takes long.

500 examples each in the default run; ``pytest --hypothesis-profile=fuzz tests/cosim/test_fuzz.py``
runs 10 000 each (the profile is registered in tests/conftest.py).
"""
from __future__ import annotations

import copy
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from feeddrive.cosim.errors import InputError
from feeddrive.cosim.recorded import Recording, load_recording
from feeddrive.cosim.scenario import Scenario, load_scenario
from feeddrive.estimator.errors import EstimatorInputError

EXAMPLES = max(500, settings().max_examples)
FUZZ = settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck), derandomize=False)
#: slowest acceptable single load [s] (a YAML bomb or a quadratic path would take far longer)
SLOW = 5.0

GOOD = {"name": "t", "step": 1e-4, "stop_time": 0.01, "plant": {"fmu": "builtin", "parameters": {"Cd": 1.2}},
        "sensors": {"seed": 1, "current": [{"gain": 1.0, "noise": 0.05}, {"noise": 0.05}]},
        "nc": {"program": [{"dwell": {"time": 0.001}}, {"rapid": {"to": 0.01, "v_max": 0.2, "accel": 0.6}}]}}
YAML_CHARS = st.sampled_from(list("ab01.-e: \n\t[]{},&*!|>'\"#%@`?~") + ["\u00e9", "\x00", "\ufeff"])
scalars = st.none() | st.booleans() | st.integers(-10**30, 10**30) | st.floats(allow_nan=True) | st.text(max_size=12)
values = st.recursive(scalars, lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner,
                                                                                          max_size=4), max_leaves=12)


def _paths(data, prefix=()):
    yield prefix
    if isinstance(data, dict):
        for k, v in data.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(data, list):
        for i, v in enumerate(data):
            yield from _paths(v, prefix + (i,))


PATHS = [p for p in _paths(GOOD) if p]


def _dump(data) -> str:
    """YAML text of ``data`` by libyaml's emitter when present: the pure-Python one was a third of this test's CPU."""
    return yaml.dump(data, Dumper=getattr(yaml, "CSafeDumper", yaml.SafeDumper))


def _mutate(data, path, value):
    data = copy.deepcopy(data)
    node = data
    for part in path[:-1]:
        node = node[part]
    node[path[-1]] = value
    return data


scenario_docs = st.one_of(
    st.text(YAML_CHARS, max_size=200),
    st.builds(lambda path, value: _dump(_mutate(GOOD, path, value)), st.sampled_from(PATHS), values),
    st.builds(lambda extra: _dump(GOOD | extra), st.dictionaries(st.text(max_size=6), values, max_size=2)),
)


def _check_error(exc: BaseException, path: Path) -> None:
    text = str(exc)
    assert isinstance(exc, (InputError, EstimatorInputError)), repr(exc)
    assert "\n" not in text.strip() and str(path) in text, text


@FUZZ
@given(scenario_docs)
def test_scenario_loader_gives_a_scenario_or_a_scenario_error(feeddrive_fmu, doc):
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "s.yaml"
        path.write_text(doc, encoding="utf-8", errors="surrogatepass")
        start = time.monotonic()
        try:
            assert isinstance(load_scenario(path), Scenario)
        except (ValueError, TypeError, KeyError, AttributeError, RecursionError, OverflowError, UnicodeError) as exc:
            _check_error(exc, path)
        assert time.monotonic() - start < SLOW


ROLES = {"time": "time", "voltage": "u", "current": "i [A]", "speed": "w"}
GOOD_ROWS = [[f"{k * 1e-3:.3f}", f"{np.sin(k):.4f}", f"{k % 5}", f"{k % 3}"] for k in range(20)]
CSV_CHARS = st.sampled_from(list("0123456789.,;-+eE \n\r\t\"'") + ["nan", "inf", "\x00", "\u00b5", "time", "u", "i [A]"])


def _csv(header, rows):
    return "\n".join(",".join(r) for r in [header] + rows) + "\n"


csv_docs = st.one_of(
    st.lists(CSV_CHARS, max_size=300).map("".join),
    st.builds(lambda r, c, cell: _csv(["time", "u", "i [A]", "w"],
                                      [row if k != r else row[:c] + [cell] + row[c + 1:] for k, row in enumerate(GOOD_ROWS)]),
              st.integers(0, 19), st.integers(0, 3), st.text(max_size=8)),
    st.builds(lambda n: _csv(["time", "u", "i [A]", "w"], GOOD_ROWS[:n]), st.integers(0, 20)),
)


@FUZZ
@given(csv_docs)
def test_csv_reader_gives_a_recording_or_a_data_error(doc):
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "r.csv"
        path.write_bytes(doc.encode("utf-8", "surrogatepass"))
        start = time.monotonic()
        try:
            rec = load_recording(path, ROLES)
        except (ValueError, TypeError, KeyError, IndexError, UnicodeError) as exc:
            _check_error(exc, path)
        else:
            assert isinstance(rec, Recording) and rec.h > 0
            assert all(np.all(np.isfinite(v)) and len(v) == rec.n for v in rec.signals.values())
        assert time.monotonic() - start < SLOW
