"""Property-based fuzzing of the readers: whatever the bytes, the only exception is DataError
(one line, naming the file), and what is accepted is finite and within the bound."""

import json
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from trajpref.data.text import GapWarning, ReadOptions, read_tracks, window_scenes
from trajpref.data.trajnet import read_trajnet
from trajpref.errors import DataError

FUZZ = settings(max_examples=150, deadline=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture])  # fmt: skip

TOKENS = ["0", "1", "-1", "10", "20", "2.5", "1e39", "-1e20", "1e5", "nan", "inf", "-inf",
          "abc", "BALL", "player", "#", ",", ";", "|", "\t", " ", "", "1_0", "0x10", "\x00",
          "é", "frame", "1e-320", "9" * 320, "\r", "\x85", "\u2028", "+", "."]  # fmt: skip
SEPS = [" ", "\t", ",", ";", ", ", "|", "  "]

token = st.one_of(
    st.sampled_from(TOKENS),
    st.integers(-(10**6), 10**6).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.text(max_size=4),
)
line = st.tuples(st.lists(token, max_size=6), st.sampled_from(SEPS)).map(lambda t: t[1].join(t[0]))
text_file = st.tuples(st.lists(line, max_size=30), st.sampled_from(["\n", "\r\n"])).map(
    lambda t: t[1].join(t[0]).encode("utf-8", "surrogatepass")
)


@st.composite
def numeric_file(draw) -> bytes:
    """Unique (frame, agent) rows of ordinary coordinates, sometimes one extreme value."""
    keys = sorted(draw(st.sets(st.tuples(st.integers(0, 7), st.integers(0, 2)), min_size=14)))
    rows = [[f * 10, a, draw(st.floats(-50, 50)), draw(st.floats(-50, 50))] for f, a in keys]
    if draw(st.booleans()):
        extreme = st.sampled_from([1e7, -3e38, 1e39, float("nan"), float("inf")])
        rows[draw(st.integers(0, len(rows) - 1))][2] = draw(extreme)
    return "".join(f"{f}\t{a}\t{x!r}\t{y!r}\n" for f, a, x, y in rows).encode()


@st.composite
def mutated_file(draw) -> bytes:
    """A valid file (3 agents x 8 frames, maybe CSV with a header) with a few lines replaced
    by random ones."""
    sep = draw(st.sampled_from(["\t", " ", ","]))
    lines = ["frame,agent,x,y"] if sep == "," and draw(st.booleans()) else []
    lines += [sep.join(map(str, (f * 10, a, f * 0.5 + a, -0.25 * f))) for f in range(8)
              for a in range(3)]  # fmt: skip
    for _ in range(draw(st.integers(0, 3))):
        i = draw(st.integers(0, len(lines)))
        lines[i:i + draw(st.integers(0, 1))] = [draw(line)]  # fmt: skip
    return "\n".join(lines).encode("utf-8", "surrogatepass")


options = st.builds(
    ReadOptions,
    delimiter=st.sampled_from([None, ",", ";", "tab", "|"]),
    max_gap=st.sampled_from([None, 0, 2]),
    max_coord=st.sampled_from([1e6, 100.0]),
)


def _read(path, data: bytes, with_type: bool, opts: ReadOptions, scale: float = 1.0):
    """Read and window; DataError is the only allowed failure. Returns scenes or None."""
    path.write_bytes(data)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy RuntimeWarnings etc. would be bugs too
        warnings.simplefilter("ignore", GapWarning)
        try:
            tracks = read_tracks(path, with_type, opts, scale=scale)
            scenes = window_scenes(tracks, 2, 3, stride=1, max_gap=opts.max_gap)
        except DataError as exc:
            assert "\n" not in str(exc) and str(exc).startswith(str(path))
            return None
    for scene in scenes:
        for arr in (scene.history, scene.future):
            assert arr.dtype == np.float32 and np.isfinite(arr).all()
            assert (np.abs(arr) <= opts.max_coord).all()
    return scenes


@FUZZ
@given(data=st.binary(max_size=400), with_type=st.booleans())
def test_random_bytes_only_raise_data_error(tmp_path, data, with_type):
    _read(tmp_path / "f.txt", data, with_type, ReadOptions())


@FUZZ
@given(data=text_file, with_type=st.booleans(), opts=options)
def test_random_lines_only_raise_data_error(tmp_path, data, with_type, opts):
    _read(tmp_path / "f.txt", data, with_type, opts)


@FUZZ
@given(data=mutated_file(), with_type=st.booleans(), opts=options)
def test_mutated_valid_files_only_raise_data_error(tmp_path, data, with_type, opts):
    _read(tmp_path / "f.txt", data, with_type, opts)


@FUZZ
@given(data=numeric_file(), opts=options, scale=st.sampled_from([1.0, 0.3048, 1e30]))
def test_random_numbers_are_read_or_refused_cleanly(tmp_path, data, opts, scale):
    _read(tmp_path / "f.txt", data, False, opts, scale)


json_value = st.recursive(
    st.none() | st.booleans() | st.integers(-5, 30) | st.floats() | st.text(max_size=3),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=2), inner),
    max_leaves=6,
)
track = st.fixed_dictionaries(
    {"f": st.integers(0, 30) | json_value, "p": st.integers(0, 3) | json_value,
     "x": st.floats(-10, 10) | json_value, "y": st.floats(-10, 10)},
    optional={"prediction_number": st.integers(0, 2) | st.none(), "scene_id": st.integers(0, 3)},
)  # fmt: skip
scene = st.fixed_dictionaries(
    {"id": st.integers(0, 5) | json_value, "p": st.integers(0, 3), "s": st.integers(0, 10),
     "e": st.integers(0, 30) | json_value},
    optional={"fps": st.floats() | json_value, "tag": json_value},
)  # fmt: skip
ndjson_line = st.one_of(
    track.map(lambda t: json.dumps({"track": t})),
    scene.map(lambda s: json.dumps({"scene": s})),
    json_value.map(json.dumps),
    st.text(max_size=10),
)


VALID_NDJSON = [
    json.dumps({"scene": {"id": i, "p": i, "s": 0, "e": 6, "fps": 2.5}}) for i in range(3)
]
VALID_NDJSON += [json.dumps({"track": {"f": f, "p": p, "x": f * 0.5, "y": p - 0.25 * f}})
                 for f in range(7) for p in range(3)]  # fmt: skip


@st.composite
def ndjson_file(draw) -> list[str]:
    """Random lines, or a valid file with a few lines replaced by random ones."""
    if draw(st.booleans()):
        return draw(st.lists(ndjson_line, max_size=40))
    lines = list(VALID_NDJSON)
    for _ in range(draw(st.integers(0, 3))):
        i = draw(st.integers(0, len(lines)))
        lines[i:i + draw(st.integers(0, 1))] = [draw(ndjson_line)]  # fmt: skip
    return lines


@FUZZ
@given(lines=ndjson_file())
def test_random_ndjson_only_raises_data_error(tmp_path, lines):
    path = tmp_path / "f.ndjson"
    path.write_text("\n".join(lines), encoding="utf-8", errors="surrogatepass")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.simplefilter("ignore", GapWarning)  # windows across a missing frame: reported
        try:
            read = read_trajnet(path, 2, 3)
        except DataError as exc:
            assert "\n" not in str(exc)
            return
    for s in read.scenes:
        assert np.isfinite(s.history).all() and np.isfinite(s.future).all()


@pytest.mark.parametrize("data", [b"", b"\n\n", b"#", b"\xef\xbb\xbf0 1 2 3\n", b"\x00" * 10])
def test_edge_files(tmp_path, data):
    assert _read(tmp_path / "f.txt", data, False, ReadOptions()) is None
