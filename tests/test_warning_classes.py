"""Every warning trajpref issues is a ``TrajprefWarning`` (a ``UserWarning``), so that an
embedding application can select them by class (library-hygiene walkthrough 69): each call
of ``warnings.warn`` under ``src/trajpref`` names a ``TrajprefWarning`` class (read from the
source), and a representative warning of each family, issued for real, is one; a filter on
the class turns them into errors or silences them. Their ``stacklevel`` keeps pointing at the
caller's line (so ``filterwarnings(module="trajpref")`` selects only some: the class all)."""

from __future__ import annotations

import ast
import warnings
from pathlib import Path

import numpy as np
import pytest
from helpers import FAST, WIDE
from synthetic import straight_rows, write_tracks

import trajpref
import trajpref.errors as errors
from trajpref.errors import (
    DataWarning,
    GapWarning,
    IgnoredWarning,
    LeftOutWarning,
    OutOfRangeWarning,
    OverlapWarning,
    TrajprefDeprecationWarning,
    TrajprefWarning,
)

SRC = Path(trajpref.__file__).parent


def _warn_calls(path: Path) -> list[tuple[int, str | None]]:
    """Each ``warnings.warn`` call of ``path``: its line and its category's source (the
    second argument or ``category=``; ``instance:f`` for a message built by a call ``f``)."""
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                and node.func.attr == "warn" and isinstance(node.func.value, ast.Name)
                and node.func.value.id == "warnings"):  # fmt: skip
            continue
        cat = node.args[1] if len(node.args) > 1 else None
        cat = cat or next((k.value for k in node.keywords if k.arg == "category"), None)
        if cat is None and node.args and isinstance(node.args[0], ast.Call):
            out.append((node.lineno, "instance:" + ast.unparse(node.args[0].func)))
        else:
            out.append((node.lineno, None if cat is None else ast.unparse(cat)))
    return out


MAKERS = {"instance:_left_out_warning": LeftOutWarning}
"""Functions that build a warning instance, and the class they build."""

FILES = sorted(str(p.relative_to(SRC)) for p in SRC.rglob("*.py") if "warnings.warn(" in
               p.read_text())  # fmt: skip


@pytest.mark.parametrize("name", FILES)
def test_every_warn_call_names_a_trajpref_warning_class(name):
    bad = []
    for line, cat in _warn_calls(SRC / name):
        cls = MAKERS.get(cat) if cat else None
        if cat and cls is None:
            cls = getattr(errors, cat.rsplit(".", 1)[-1], None)
        if not (isinstance(cls, type) and issubclass(cls, TrajprefWarning)):
            bad.append(f"{name}:{line} {cat}")
    assert not bad, bad


def test_the_sources_read_are_the_librarys():
    assert {"evaluation.py", "score/scorer.py", "data/text.py", "models/timing.py"} <= set(FILES)
    assert len(_warn_calls(SRC / "score" / "scorer.py")) >= 6


# --- warnings issued for real ----------------------------------------------------------------

T = np.arange(8)[:, None]


def _record(call) -> list[warnings.WarningMessage]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        call()
    return list(caught)


def _one(call, cls: type[Warning], match: str, here: bool = True) -> warnings.WarningMessage:
    """The one warning of ``call`` whose text holds ``match``, checked to be a ``cls`` and a
    ``TrajprefWarning``; ``here``: shown at this file's line (its ``stacklevel``)."""
    caught = [w for w in _record(call) if match in str(w.message)]
    assert len(caught) == 1, [str(w.message) for w in _record(call)]
    assert issubclass(caught[0].category, cls) and issubclass(caught[0].category, TrajprefWarning)
    assert not here or caught[0].filename == __file__  # still the caller's line
    return caught[0]


def test_a_wide_scene_and_other_units_from_predict_scene_are_out_of_range(zara1):
    from trajpref.score import predict_scene

    walker = T * np.array([0.5, 0.0])
    wide = np.stack([walker, walker + [0.0, 1000.0]]).astype(np.float32)  # 1 km apart
    _one(lambda: predict_scene(zara1, wide), OutOfRangeWarning, WIDE)
    near = np.stack([walker, walker + [0.0, 2.0]]).astype(np.float32)
    _one(lambda: predict_scene(zara1, near, frame_interval=0.1), OutOfRangeWarning, "0.1 s")


def test_fast_agents_from_predict_scene_are_out_of_range(robo):
    from trajpref.score import predict_scene

    fast = np.stack([T * [3.8, 0.0] + [0.0, dy] for dy in (0.0, 2.0, 4.0)]).astype(np.float32)
    _one(lambda: predict_scene(robo, fast), OutOfRangeWarning, FAST)


def test_fewer_samples_than_a_fixed_set_is_a_trajpref_warning(zara1):
    from trajpref.score import predict_scene

    walker = T * np.array([0.5, 0.0])
    history = np.stack([walker, walker + [0.0, 2.0]]).astype(np.float32)
    _one(lambda: predict_scene(zara1, history, num_samples=5), TrajprefWarning,
         "num_samples=5 takes its first 5")  # fmt: skip


def test_a_gap_in_a_text_file_is_a_gap_warning_that_a_filter_makes_an_error(tmp_path):
    from trajpref.data.text import read_folder

    frames = [10 * i for i in range(10)] + [10 * i for i in range(15, 25)]
    write_tracks(tmp_path / "a.txt", [(f, 1, f / 10, 0) for f in frames])
    _one(lambda: read_folder(tmp_path, 8, 12), GapWarning, "windows", here=False)
    with warnings.catch_warnings():
        warnings.filterwarnings("error", category=TrajprefWarning)
        with pytest.raises(GapWarning):
            read_folder(tmp_path, 8, 12)
    with pytest.warns(TrajprefWarning):
        read_folder(tmp_path, 8, 12)
    with warnings.catch_warnings():  # the README's line: every trajpref warning silenced
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", category=errors.TrajprefWarning)
        assert read_folder(tmp_path, 8, 12)


def test_evaluation_data_checks_are_out_of_range_or_overlap():
    from trajpref.evaluation import check_trained_on
    from trajpref.models.timing import model_timing
    from trajpref.types import DatasetInfo

    header = {"config": {"data": {"dataset": "zara1"}}}
    model, data = model_timing(header), header["config"]["data"]
    train = DatasetInfo("zara1", "train", "m", 0.4, 8, 12, "src")
    _one(lambda: check_trained_on("this model", model, data, train), OverlapWarning,
         "trained on these windows")  # fmt: skip
    other = DatasetInfo("mine", "test", "px", 0.1, 8, 12, "src")
    _one(lambda: check_trained_on("this model", model, data, other), OutOfRangeWarning,
         "this data is in px")  # fmt: skip
    with warnings.catch_warnings():
        warnings.filterwarnings("error", category=TrajprefWarning)
        with pytest.raises(OverlapWarning):
            check_trained_on("this model", model, data, train)


def test_data_and_ignored_argument_warnings(tmp_path, data_root):
    from trajpref.data import load_dataset

    write_tracks(tmp_path / "mine" / "a.txt", straight_rows(24))
    _one(lambda: load_dataset(str(tmp_path / "mine"), "test", units="furlongs"), DataWarning,
         "units 'furlongs'")  # fmt: skip
    _one(lambda: load_dataset("zara1", "test", data_root, frame_interval=0.1), IgnoredWarning,
         "is ignored")  # fmt: skip


def test_a_left_out_agent_is_a_data_warning():
    from trajpref.data import tracks_to_history

    times = 100 + 0.1 * np.arange(40)
    times[-1] -= 0.011
    times = np.r_[times, 104.005]  # the current cycle's stamp 5 ms after now
    xy = np.stack([1.4 * (times - 100), np.zeros_like(times)], -1)
    caught = _one(lambda: tracks_to_history(times, np.zeros(len(times), dtype=int), xy,
                                            now=104.0, step=0.4),
                  LeftOutWarning, "left out")  # fmt: skip
    assert issubclass(caught.category, DataWarning) and caught.message.suggested_hold > 0


def test_a_legacy_config_key_is_a_deprecation_and_still_a_future_warning():
    from trajpref.config import upgrade_config_dict

    caught = _one(lambda: upgrade_config_dict({"generator": {"samples": 20}}),
                  TrajprefDeprecationWarning, "is now model.samples")  # fmt: skip
    assert issubclass(caught.category, FutureWarning)
    with pytest.warns(FutureWarning, match="generator.samples is now"):
        upgrade_config_dict({"generator": {"samples": 20}})


def test_the_readmes_errors_and_warnings_block_runs(tmp_path, monkeypatch, capsys):
    import re

    readme = Path(__file__).resolve().parents[1] / "README.md"
    python = readme.read_text().split("## Python API", 1)[1].split("\n## ", 1)[0]
    section = python.split("### Errors and warnings", 1)[1]
    for name in re.findall(r"^\| `(\w+)`", section, re.M):  # the table names real classes
        assert isinstance(getattr(errors, name), type), name
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    assert 'filterwarnings("ignore", category=trajpref.errors.TrajprefWarning)' in code
    monkeypatch.chdir(tmp_path)  # no runs/mine/ here
    with warnings.catch_warnings(record=True) as caught:  # the block's filter stays here
        warnings.simplefilter("always")
        exec(compile(code, str(readme), "exec"), {})  # noqa: S102 - our own README
        warnings.warn("silenced", OverlapWarning, stacklevel=1)
        warnings.warn("shown", UserWarning, stacklevel=1)
    assert [str(w.message) for w in caught] == ["shown"]
    assert capsys.readouterr().out.startswith("no model: runs/mine/generator.safetensors")
