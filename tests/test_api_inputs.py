"""What a notebook user hands the Python API, checked where it enters (walkthrough 66): seeds
and score steps as numpy integers or nonsense, figures of lists, tensors and predict_scene's
output without ground truth, a folder's frame interval and units, the constant-velocity
baseline's one-step history and its step and units, the lazy subpackages of ``import
trajpref``, and the selection settings' types. Each case raised a raw TypeError, ValueError,
IndexError or AttributeError (or was silently accepted) before."""

from __future__ import annotations

import inspect
import json
import math
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

import trajpref
from trajpref.data import load_dataset
from trajpref.errors import ConfigError, DataError
from trajpref.models.baseline import ConstantVelocity
from trajpref.models.registry import load_predictor
from trajpref.score import TrajectoryScorer, predict_scene, predict_scenes, rank_samples
from trajpref.score.selection import SelectionConfig, select_for_scene
from trajpref.viz.plot import plot_scene, plot_scene_scored

README = Path(__file__).resolve().parents[1] / "README.md"
SRC = Path(trajpref.__file__).resolve().parent


@pytest.fixture(scope="module")
def scorer() -> TrajectoryScorer:
    return TrajectoryScorer.from_checkpoint("zara1/denoiser", steps=[0])


@pytest.fixture(scope="module")
def cv():
    return load_predictor("cv")


def _scene(p: int = 2) -> np.ndarray:
    """history [P, 8, 2]: walkers 1.2 m/s apart by 2 m."""
    t = np.arange(8, dtype=np.float64)[:, None]
    return np.stack([np.hstack([0.48 * t, 0 * t + 2.0 * a]) for a in range(p)])


# 1. seeds -------------------------------------------------------------------------------


def test_a_numpy_integer_seed_is_the_int_seed(cv):
    h = _scene()
    a = predict_scene(cv, h, 5, seed=np.int64(3))
    assert np.array_equal(a, predict_scene(cv, h, 5, seed=3))
    assert not np.array_equal(a, predict_scene(cv, h, 5, seed=4))  # the seed is read
    batch = predict_scenes(cv, [h, h[:1]], 5, seed=np.uint8(3))
    assert len(batch) == 2


@pytest.mark.parametrize("seed", [None, 0.5, "3", True, 2**70, -(2**63) - 1, np.float64(2)])
def test_a_seed_that_is_no_integer_is_a_config_error(cv, seed):
    with pytest.raises(ConfigError, match="seed must be an integer"):
        predict_scene(cv, _scene(), 5, seed=seed)


def test_the_seed_range_is_torchs():
    for seed in (2**64 - 1, -(2**63), -1):
        assert predict_scene(ConstantVelocity(), _scene(), 2, seed=seed).shape == (2, 2, 12, 2)


def test_a_scorer_seed_is_checked_when_built_and_set(scorer):
    h = _scene()
    samples = predict_scene(ConstantVelocity(), h, 4, seed=0)
    numpy_seeded = TrajectoryScorer.from_checkpoint("zara1/denoiser", steps=[0], seed=np.int64(1))
    assert numpy_seeded.seed == 1 and type(numpy_seeded.seed) is int
    plain = TrajectoryScorer.from_checkpoint("zara1/denoiser", steps=[0], seed=1)
    for a, b in zip(rank_samples(numpy_seeded, h, samples), rank_samples(plain, h, samples),
                    strict=True):  # fmt: skip
        assert np.array_equal(a, b)
    for seed in (None, 2**70, 1.5):
        with pytest.raises(ConfigError, match="seed must be an integer"):
            TrajectoryScorer.from_checkpoint("zara1/denoiser", steps=[0], seed=seed)
    other = scorer.with_steps([0, 3])
    with pytest.raises(ConfigError, match="seed must be an integer"):
        other.seed = "7"
    other.seed = np.int32(7)
    assert other.seed == 7


def test_a_selection_seed_is_checked():
    assert SelectionConfig(seed=np.int64(2)).seed == 2
    for seed in (None, 0.5, 2**70):
        with pytest.raises(ConfigError, match="selection seed must be an integer"):
            SelectionConfig(seed=seed)


# 2. figures -------------------------------------------------------------------------------


def test_plot_scene_draws_predict_scenes_output_without_ground_truth(cv, tmp_path):
    h = _scene()
    futures = predict_scene(cv, h, 5)
    assert plot_scene(h, None, futures, tmp_path / "a.png").stat().st_size > 0
    out = plot_scene(h, None, futures, tmp_path / "a.svg")
    assert 'id="truth-0"' not in out.read_text()  # no ground truth drawn
    assert "ground truth" not in out.read_text()  # nor named in the legend


def _drawn(fig) -> str:
    """What a figure shows, axis by axis: its lines' points, its markers' positions and where
    its texts are (as JSON text, which compares NaN, a break in a line, as equal)."""
    return json.dumps([([line.get_xydata().tolist() for line in ax.lines],
                        [np.asarray(c.get_offsets()).tolist() for c in ax.collections],
                        [(t.get_text(), list(t.get_position())) for t in ax.texts])
                       for ax in fig.axes])  # fmt: skip


def test_plots_take_lists_and_tensors(cv, tmp_path, monkeypatch):
    """Lists and (bf16) tensors draw what the same numbers as numpy arrays draw."""
    import trajpref.viz.plot as plot

    figures, save = [], plot._save

    def keep(fig, out, *args, **kwargs):
        figures.append(_drawn(fig))
        return save(fig, out, *args, **kwargs)

    monkeypatch.setattr(plot, "_save", keep)
    h = _scene()
    futures = predict_scene(cv, h, 5)
    futures[:, 1] += np.linspace(-0.3, 0.3, 5)[:, None, None]  # five different samples
    fut = futures[0]
    scores = np.array([[0.1, 0.5], [0.4, -0.2], [0.3, 0.0], [-0.1, 0.2], [0.2, 0.1]])  # [K, P]
    plot_scene(h, fut, futures, tmp_path / "n.png", agent_type=np.array([0, 1]))
    plot_scene(h.tolist(), fut.tolist(), futures.tolist(), tmp_path / "l.png", agent_type=[0, 1])
    assert figures[1] == figures[0]
    plot_scene_scored(h, fut, futures, scores, tmp_path / "n2.png")
    plot_scene_scored(h.tolist(), fut, futures, scores.tolist(), tmp_path / "s2.png")
    assert figures[3] == figures[2]
    tensors = [torch.as_tensor(x, dtype=torch.bfloat16) for x in (h, fut, futures)]
    rounded = [t.float().numpy() for t in tensors]  # the same numbers, as numpy arrays
    plot_scene(*rounded, tmp_path / "n3.png", agent_type=np.array([0, 0]))
    plot_scene(*tensors, tmp_path / "t.png", agent_type=torch.tensor([0, 0]))
    assert figures[5] == figures[4]
    plot_scene_scored(*rounded, scores, tmp_path / "n4.png")
    plot_scene_scored(*tensors, torch.as_tensor(scores), tmp_path / "s.png")
    assert figures[7] == figures[6]
    assert figures[0] != figures[4] and figures[2] != figures[6]  # the bf16 rounding shows


def test_plot_shapes_that_do_not_fit_are_data_errors(cv, tmp_path):
    h = _scene()
    futures = predict_scene(cv, h, 5)  # [5, 2, 12, 2]
    out = tmp_path / "a.png"
    with pytest.raises(DataError, match=r"pred: expected \[K, 2, 12, 2\].*transpose\(1, 0, 2, 3\)"):
        plot_scene(h, futures[0], futures.transpose(1, 0, 2, 3), out)
    with pytest.raises(DataError, match=r"pred: .*got \[2, 12, 2\] \(one sample\? .*pred\[None\]"):
        plot_scene(h, futures[0], futures[0], out)
    with pytest.raises(DataError, match=r"future: expected \[2, T_f, 2\].*got \[1, 12, 2\]"):
        plot_scene(h, futures[0, :1], futures, out)
    with pytest.raises(DataError, match=r"pred: expected \[K, 2, 12, 2\].*got \[5, 2, 11, 2\]"):
        plot_scene(h, futures[0], futures[:, :, :11], out)
    with pytest.raises(DataError, match=r"history: expected \[P, T_h, 2\].*got \[8, 2\]"):
        plot_scene(h[0], None, None, out)
    with pytest.raises(DataError, match="history must be an array"):
        plot_scene(None, None, futures, out)
    with pytest.raises(DataError, match=r"agent_type: expected \[2\]"):
        plot_scene(h, None, futures, out, agent_type=[0, 1, 0])
    with pytest.raises(DataError, match="expected an array of numbers"):
        plot_scene([[1, 2], [3]], None, None, out)
    with pytest.raises(ConfigError, match="max_samples"):
        plot_scene(h, None, futures, out, max_samples="2")


def test_plot_scene_scored_refuses_rank_samples_residual_with_a_hint(cv, scorer, tmp_path):
    h = _scene()
    futures = predict_scene(cv, h, 5)
    _, residual = rank_samples(scorer, h, futures)  # [K], lower is better
    out = tmp_path / "s.png"
    with pytest.raises(
        DataError,
        match=r"scores: expected \[5, 2\] .*higher is better.*1-D \[5\]"
        r".*rank_samples' residual.*-np.repeat\(residual\[:, None\], 2, 1\)",
    ):
        plot_scene_scored(h, futures[0], futures, residual, out)
    plot_scene_scored(h, futures[0], futures, -np.repeat(residual[:, None], 2, 1), out)
    with pytest.raises(DataError, match=r"scores: expected \[5, 2\].*got \[2, 5\].*scores\.T"):
        plot_scene_scored(h, futures[0], futures, np.zeros((2, 5)), out)
    with pytest.raises(DataError, match="future: the first panel draws the ground truth"):
        plot_scene_scored(h, None, futures, np.zeros((5, 2)), out)
    with pytest.raises(ConfigError, match="top"):
        plot_scene_scored(h, futures[0], futures, np.zeros((5, 2)), out, top="2")
    doc = inspect.getdoc(plot_scene_scored)
    assert "HIGHER IS BETTER" in doc and "rank_samples" in doc


def test_a_figures_width_that_is_no_number_is_a_config_error(tmp_path):
    with pytest.raises(ConfigError, match="width"):
        plot_scene(_scene(), None, None, tmp_path / "a.png", width="3")


# 3. a folder's frame interval and units ----------------------------------------------------


@pytest.fixture
def folder(tmp_path) -> Path:
    rows = [f"{f * 10} {a} {f * 0.5} {2 * a}" for f in range(30) for a in (1, 2)]
    (tmp_path / "walks.txt").write_text("\n".join(rows) + "\n")
    return tmp_path


@pytest.mark.parametrize("interval", ["0.4", 0, -0.4, math.nan, math.inf, True, [0.4]])
def test_a_frame_interval_that_is_no_positive_number_is_a_config_error(folder, interval):
    with pytest.raises(ConfigError, match="frame_interval: seconds between .* a number > 0"):
        load_dataset(str(folder), "test", frame_interval=interval)


def test_a_numpy_frame_interval_counts(folder):
    info = load_dataset(str(folder), "test", frame_interval=np.float32(0.5)).info
    assert info.frame_interval == 0.5 and type(info.frame_interval) is float


def test_units_are_a_name(folder):
    for units in (3, "", "  ", ["m"]):
        with pytest.raises(ConfigError, match="units: a unit name"):
            load_dataset(str(folder), "test", units=units)
    assert load_dataset(str(folder), "test", units=None).info.units == "unknown"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the names the library knows: no warning
        for units in ("m", "Meters", "px", "pixels", "ft", "unknown"):
            assert load_dataset(str(folder), "test", units=units).info.units == units
    with pytest.warns(UserWarning, match="units 'furlongs' is none of the names trajpref knows"):
        assert load_dataset(str(folder), "test", units="furlongs").info.units == "furlongs"


def test_the_known_unit_names_are_the_librarys():
    from trajpref.data.registry import KNOWN_UNITS, PIXEL_NAMES
    from trajpref.metrics import METRE_UNITS
    from trajpref.models.timing import PIXEL_UNITS
    from trajpref.viz.plot import IMAGE_UNITS

    assert METRE_UNITS <= KNOWN_UNITS and PIXEL_NAMES == PIXEL_UNITS == set(IMAGE_UNITS)


def test_a_built_in_dataset_ignores_a_folders_description_and_says_so(data_root):
    with pytest.warns(UserWarning, match=r"zara1 knows its own \(m, 0.4 s\), so "
                      r"frame_interval=0.1 and units='px' are ignored"):  # fmt: skip
        info = load_dataset("zara1", "test", data_root, frame_interval=0.1, units="px").info
    assert (info.frame_interval, info.units) == (0.4, "m")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_dataset("zara1", "test", data_root)


def test_a_run_with_a_built_in_training_set_describes_its_validation_folder_only(data_root, folder):
    from trajpref.config import DataConfig
    from trajpref.data import run_splits

    cfg = DataConfig(dataset="zara1", val_dataset=str(folder), frame_interval=0.5, units="m")
    with warnings.catch_warnings():
        warnings.filterwarnings("error", message=".*describe a folder dataset")
        train, val = run_splits(cfg, data_root)
    assert (train.info.frame_interval, val.info.frame_interval) == (0.4, 0.5)


# 4. the constant-velocity baseline --------------------------------------------------------


def test_constant_velocity_needs_two_observed_steps(cv):
    with pytest.raises(DataError, match="constant velocity needs at least 2 observed steps"):
        predict_scene(cv, _scene()[:, :1])
    assert predict_scene(cv, _scene()[:, -2:], 1).shape == (1, 2, 12, 2)


def test_constant_velocity_knows_no_step_units_or_history_length(cv):
    assert (cv.frame_interval, cv.units, cv.t_hist) == (None, None, None)


# 5. score steps ---------------------------------------------------------------------------


def test_score_steps_take_numpy_integers_and_refuse_fractions(scorer):
    built = TrajectoryScorer.from_checkpoint("zara1/denoiser", steps=np.arange(0, 100, 3))
    assert built.steps == list(range(0, 100, 3)) and all(type(s) is int for s in built.steps)
    assert built.with_steps(np.arange(0, 100, 3)) is built
    assert scorer.with_steps(np.array([0, 9])).steps == [0, 9]
    assert scorer.with_steps(torch.tensor([3])).steps == [3]
    for steps in ([0.5], 5, "0", [], [100], [-1], np.zeros((2, 2), int), [None]):
        with pytest.raises(ConfigError, match="score steps"):
            TrajectoryScorer.from_checkpoint("zara1/denoiser", steps=steps)
        with pytest.raises(ConfigError, match="score steps"):
            scorer.with_steps(steps)


# 6. import trajpref -----------------------------------------------------------------------


def test_import_trajpref_reaches_the_subpackages_on_first_use():
    code = (
        "import sys, trajpref\n"
        "loaded = sorted(m for m in sys.modules if m.startswith('trajpref.'))\n"
        "assert loaded == ['trajpref.errors'], loaded\n"
        "assert callable(trajpref.evaluation.evaluate)\n"
        "assert callable(trajpref.config.load_config)\n"
        "assert callable(trajpref.rl.register_reward)\n"
        "assert callable(trajpref.data.load_dataset)\n"
        "assert 'trajpref.cli' not in sys.modules\n"
        "try:\n"
        "    trajpref.nothing\n"
        "except AttributeError as exc:\n"
        "    assert \"no attribute 'nothing'\" in str(exc)\n"
        "else:\n"
        "    raise AssertionError('trajpref.nothing')\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True)


def test_the_lazy_names_are_every_module_and_help_names_the_entry_points():
    here = {p.stem for p in SRC.glob("*.py")} | {p.parent.name for p in SRC.glob("*/__init__.py")}
    named = set(trajpref.SUBPACKAGES) | set(trajpref.ENTRY_MODULES)
    assert named == here - {"__init__", "__main__"}
    # viz, cli, demo and survey are left out of dir() until imported, so that help() and
    # inspect.getmembers do not import them (tests/test_package_namespace.py)
    assert set(trajpref.__all__) | (named - set(trajpref.UNLISTED)) <= set(dir(trajpref))
    for entry in ("load_predictor", "predict_scene", "rank_samples", "select_for_scene",
                  "load_dataset", "evaluate", "load_config", "train_stage", "register_reward",
                  "finetune_config", "plot_scene"):  # fmt: skip
        assert entry in trajpref.__doc__, entry


def test_a_star_import_loads_no_subpackage_and_keeps_matplotlibs_backend():
    """Review of walkthrough 66: ``__all__`` listed every subpackage, so ``from trajpref
    import *`` imported them all, viz among them, which switched matplotlib to Agg."""
    assert trajpref.__all__ == ["ONEDNN_CACHE_CAPACITY", "TrajprefError", "__version__"]
    code = (
        "import sys, matplotlib\n"
        "matplotlib.use('pdf')\n"
        "from trajpref import *\n"
        "assert matplotlib.get_backend() == 'pdf', matplotlib.get_backend()\n"
        "loaded = sorted(m for m in sys.modules if m.startswith('trajpref.'))\n"
        "assert loaded == ['trajpref.errors'], loaded\n"
        "assert ONEDNN_CACHE_CAPACITY and TrajprefError and __version__\n"
        "import trajpref\n"
        "assert callable(trajpref.evaluation.evaluate)\n"  # still served on first use
        "assert 'evaluation' in dir(trajpref)\n"
        "assert not {'viz', 'cli'} & set(dir(trajpref))\n"  # listed once imported
    )
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True)


def test_the_readme_qualifies_finetune_config():
    python = README.read_text().split("## Python API", 1)[1].split("\n## ", 1)[0]
    for i in range(len(python)):
        if python.startswith("finetune_config(", i):
            assert python[:i].endswith("trajpref.rl.presets."), python[i - 80 : i + 20]
    assert "train.run.finetune" not in python


# 7. type hints ----------------------------------------------------------------------------


def test_from_checkpoint_says_what_it_takes():
    params = inspect.signature(TrajectoryScorer.from_checkpoint).parameters
    assert "PathLike" in str(params["path"].annotation)
    assert "device" in str(params["device"].annotation)
    for name in ("steps", "seed", "shared_noise", "speed_ref", "precision", "neighbour_radius"):
        assert params[name].kind is inspect.Parameter.KEYWORD_ONLY, name
        assert params[name].annotation is not inspect.Parameter.empty, name
    assert not any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values())


# 8. selection settings ---------------------------------------------------------------------


@pytest.mark.parametrize("field", ["drop", "trust_speed", "bandwidth", "temperature"])
def test_selection_numbers_that_are_strings_are_config_errors(field):
    with pytest.raises(ConfigError, match=f"selection {field} must be a number, got '0.4'"):
        SelectionConfig(**{field: "0.4"})
    with pytest.raises(ConfigError, match=f"selection {field} must be a number"):
        SelectionConfig(**{field: None})
    assert getattr(SelectionConfig(**{field: np.float32(0.25)}), field) == 0.25


def test_selection_iters_and_final_are_checked():
    with pytest.raises(ConfigError, match="selection iters must be an integer"):
        SelectionConfig(iters=2.5)
    with pytest.raises(ConfigError, match="selection final must be True or False"):
        SelectionConfig(final="yes")
    assert SelectionConfig(final=np.bool_(True)).final is True


# 9. histories that are no array ------------------------------------------------------------


def test_a_history_that_is_no_array_is_named_so(cv, scorer):
    with pytest.raises(DataError, match=r"history must be an array \[P, T_h, 2\].*got None"):
        predict_scene(cv, None)
    with pytest.raises(DataError, match=r"history must be an array \[P, 8, 2\].*got None"):
        predict_scene(load_predictor("zara1/generator"), None)
    with pytest.raises(DataError, match=r"history must be an array .*a single value \(3.0\)"):
        predict_scene(cv, np.float64(3.0))
    with pytest.raises(DataError, match=r"histories\[1\] must be an array"):
        predict_scenes(cv, [_scene(), None])
    with pytest.raises(DataError, match="histories must be a list"):
        predict_scenes(cv, None)
    samples = predict_scene(cv, _scene(), 4)
    with pytest.raises(DataError, match=r"history must be an array \[P, 8, 2\].*got None"):
        rank_samples(scorer, None, samples)
    with pytest.raises(DataError, match=r"samples must be an array \[K, P, 12, 2\].*got None"):
        select_for_scene(scorer, _scene(), None, SelectionConfig(keep=2))
