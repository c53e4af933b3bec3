"""Everything a user can get wrong, across the sub-commands: one line on stderr
(``trajpref: error: ...``), exit status 2, nothing on stdout, and nothing written anywhere
(the output location, the inputs, the run folder a state was read from).

Each case is (sub-command and options, a regex the one line must match). Placeholders:
``{walks}`` a good dataset folder, ``{run}`` a trained tiny run (both stages, with their
``_last.pt`` states), ``{in}`` bad inputs made once per session, ``{out}`` a fresh output
folder per case that already holds ``afile``, ``taken.npz/``, ``taken.png/`` and ``taken.json/``.
The checks run in process through ``trajpref.cli.main`` on tiny synthetic data.
"""

from __future__ import annotations

import os
import random
import re
from pathlib import Path

import pytest
import torch
from synthetic import TINY_OVERRIDES, straight_rows, write_tracks

import trajpref.cli as cli
from trajpref.cli import main

TINY = [a for o in TINY_OVERRIDES for a in ("--set", o)]
"""The tiny model's config as ``--set`` options (train and finetune cases)."""
TRAIN = ["train", "diffusion", "--set", "data.dataset={walks}", *TINY, "--device", "cpu",
         "--no-progress"]  # fmt: skip
GEN = ["train", "generator", "--set", "data.dataset={walks}", *TINY, "--device", "cpu",
       "--no-progress"]  # fmt: skip
FT = ["finetune", "--method", "rlhf-res", "--device", "cpu", "--no-progress"]
EVAL = ["evaluate", "--dataset", "{walks}", "--no-progress", "--device", "cpu"]
PRED = ["predict", "--dataset", "{walks}", "--no-progress", "--device", "cpu"]
PLOT = ["plot", "--dataset", "{walks}", "--device", "cpu"]
STATS = ["data", "stats"]

CASES: dict[str, tuple[list[str], str]] = {
    # --- argument parsing: the same one-line form as every other error
    "unknown option": ([*EVAL, "--bogus"], r"unrecognized arguments: --bogus"),
    "bad choice": ([*STATS, "--dataset", "{walks}", "--split", "dev"],
                   r"argument --split: invalid choice: 'dev'"),
    "not an integer": ([*EVAL, "--samples", "many"], r"argument --samples: invalid int value"),
    "missing required --out": (PRED, r"required: --out"),
    # --- data: missing or malformed input
    "missing folder": ([*STATS, "--dataset", "{in}/nope"], r"no such folder"),
    "a file, not a folder": ([*STATS, "--dataset", "{in}/nan/good.txt"],
                             r"good\.txt: a file, where a folder of track files is needed"),
    "unknown dataset name": ([*STATS, "--dataset", "zara9"], r"unknown dataset 'zara9'"),
    "too few columns": ([*STATS, "--dataset", "{in}/cols"], r"bad\.txt:1: .*4 columns"),
    "NaN coordinate": ([*STATS, "--dataset", "{in}/nan"], r"bad\.txt:1: .*(NaN|finite)"),
    "empty file": ([*STATS, "--dataset", "{in}/empty"], r"bad\.txt: .*empty"),
    "frame interval 0": ([*STATS, "--dataset", "{walks}", "--frame-interval", "0"],
                         r"--frame-interval must be .* > 0"),
    "frame interval nan": ([*STATS, "--dataset", "{walks}", "--frame-interval", "nan"],
                           r"--frame-interval must be .* > 0"),
    # --- evaluate
    "samples 0": ([*EVAL, "--samples", "0"], r"--samples must be >= 1"),
    "max agents 0": ([*EVAL, "--max-agents", "0"], r"--max-agents must be >= 1"),
    "unknown device": ([*EVAL, "--device", "tpu"], r"unknown device 'tpu'"),
    "missing model file": ([*EVAL, "--model", "{in}/nope.safetensors"], r"no such model"),
    "a sampler for cv": ([*EVAL, "--model", "cv", "--sampler", "full"],
                         r"--sampler applies to diffusion checkpoints; --model cv has none"),
    "a run folder as the model": ([*EVAL, "--model", "{run}"],
                                  r"a folder, not a checkpoint file: pass .*generator\.safet"),
    "random bytes as model": ([*EVAL, "--model", "{in}/rand.safetensors"],
                              r"rand\.safetensors: not a trajpref checkpoint"),
    "pickle protocol 105 as model": ([*EVAL, "--model", "{in}/proto105.pt"],
                                     r"proto105\.pt: not a loadable checkpoint"),
    "missing scorer": ([*EVAL, "--scorer", "{in}/nope.safetensors"], r"no such checkpoint"),
    "keep 0": ([*EVAL, "--keep", "0"], r"--keep must lie in 1\.\.--samples \(20\)"),
    "keep > samples": ([*EVAL, "--samples", "5", "--keep", "6"], r"--keep must lie in 1\.\."),
    "score selection without scorer": ([*EVAL, "--keep", "5", "--select", "top"],
                                       r"--select top with --model cv needs --scorer"),
    "deterministic cv": ([*EVAL, "--deterministic"], r"--deterministic applies to diffusion"),
    "max speed for cv": ([*EVAL, "--max-speed", "0.4"], r"--max-speed applies to generator"),
    "negative max speed": ([*EVAL, "--model", "{run}/generator.safetensors", "--max-speed", "-1"],
                           r"--max-speed: model\.max_speed must be >= 0"),
    "spread scale for cv": ([*EVAL, "--spread-scale", "1.2"], r"--spread-scale applies to gen"),
    "zero spread scale": ([*EVAL, "--model", "{run}/generator.safetensors", "--spread-scale", "0"],
                          r"--spread-scale: model\.spread_scale must be > 0"),
    "nan sigma cap": ([*EVAL, "--model", "{run}/generator.safetensors", "--max-log-sigma", "nan"],
                      r"--max-log-sigma: model\.max_log_sigma must be a finite number"),
    "leapfrog without generator": (
        [*EVAL, "--model", "{run}/denoiser.safetensors", "--sampler", "leapfrog"],
        r"leapfrog sampler needs a generator"),
    "eval --out is a folder": ([*EVAL, "--out", "{out}/taken.json"],
                               r"--out .*taken\.json: is an existing folder, not a file"),
    "eval --out in /sys": ([*EVAL, "--out", "/sys/trajpref-eval.json"],
                           r"--out /sys/trajpref-eval\.json: cannot write in /sys"),
    "eval --out in /proc": ([*EVAL, "--out", "/proc/trajpref-eval.json"],
                            r"--out /proc/trajpref-eval\.json: cannot write in /proc"),
    "eval --out under a file": ([*EVAL, "--out", "{out}/afile/e.json"],
                                r"--out .*: .*afile is not a folder"),
    "eval bad data with --out": (["evaluate", "--dataset", "{in}/nan", "--out", "{out}/e.json"],
                                 r"bad\.txt:1: .*(NaN|finite)"),
    # --- predict
    "predict --out not .npz": ([*PRED, "--out", "{out}/p.txt"], r"must be a \.npz file"),
    "predict --out is a folder": ([*PRED, "--out", "{out}/taken.npz"],
                                  r"taken\.npz: is an existing folder"),
    "predict --out in /sys": ([*PRED, "--out", "/sys/p.npz"], r"cannot write in /sys"),
    "predict --out under a file": ([*PRED, "--out", "{out}/afile/deeper/p.npz"],
                                   r"afile is not a folder"),
    "rank cv without scorer": ([*PRED, "--rank", "--out", "{out}/p.npz"],
                               r"--rank with --model cv needs --scorer"),
    "predict missing data": (["predict", "--dataset", "{in}/nope", "--out", "{out}/new/p.npz"],
                             r"no such folder"),
    # --- plot
    "plot --out not .png": ([*PLOT, "--out", "{out}/s.jpg"], r"must be a \.png file"),
    "plot --out is a folder": ([*PLOT, "--out", "{out}/taken.png"], r"is an existing folder"),
    "plot --out in /proc": ([*PLOT, "--out", "/proc/s.png"], r"cannot write in /proc"),
    "scene out of range": ([*PLOT, "--scene", "99", "--out", "{out}/s.png"],
                           r"--scene 99: the split has scenes 0\.\.4"),
    "negative scene": ([*PLOT, "--scene", "-1", "--out", "{out}/s.png"], r"start at 0"),
    # --- train: the run folder and --resume, checked before anything is read or written
    "train --out is a file": ([*TRAIN, "--out", "{out}/afile"], r"exists and is not a folder"),
    "train --out in /sys": ([*TRAIN, "--out", "/sys/trajpref-run"], r"cannot write in /sys"),
    "train --out under a file": ([*TRAIN, "--out", "{out}/afile/run"], r"afile is not a folder"),
    "resume missing file": ([*TRAIN, "--out", "{out}/run", "--resume", "{in}/nope_last.pt"],
                            r"--resume .*nope_last\.pt: no such file"),
    "resume random bytes": ([*TRAIN, "--out", "{out}/run", "--resume", "{in}/rand.bin"],
                            r"--resume .*rand\.bin: not a resume state .*denoiser_last\.pt"),
    "resume pickle protocol 105": (
        [*TRAIN, "--out", "{out}/run", "--resume", "{in}/proto105.pt"],
        r"--resume .*proto105\.pt: not a resume state .*denoiser_last\.pt"),
    "resume a folder": ([*TRAIN, "--out", "{out}/run", "--resume", "{run}"],
                        r"is a folder; pass denoiser_last\.pt inside it"),
    "resume the wrong stage": (
        [*GEN, "--denoiser", "{run}/denoiser.safetensors", "--out", "{out}/run", "--resume",
         "{run}/denoiser_last.pt"],
        r"the state of a denoiser stage, not of generator; pass generator_last\.pt"),
    "resume a best checkpoint": (
        [*TRAIN, "--out", "{out}/run", "--resume", "{run}/denoiser.safetensors"],
        r"a best checkpoint \(weights only\) cannot be resumed; pass denoiser_last\.pt"),
    "resume a legacy model checkpoint": (
        [*TRAIN, "--out", "{out}/run", "--resume", "{in}/legacy.pt"],
        r"a model checkpoint \(denoiser\) cannot be resumed"),
    "resume a torch file of another kind": (
        [*TRAIN, "--out", "{out}/run", "--resume", "{in}/tensor.pt"],
        r"not a resume state \(no keys\)"),
    "resume into another model size": (
        [*TRAIN, "--set", "model.hidden=32", "--out", "{run}", "--resume",
         "{run}/denoiser_last.pt"],
        r"differs from the one that wrote the state \(model\.hidden: \d+ -> 32\); resume "
        r"with its config as it was \(--config .*denoiser_config\.yaml\)"),
    "resume into another folder": (
        [*TRAIN, "--out", "{out}/run", "--resume", "{run}/denoiser_last.pt"],
        r"a run resumes in its own folder \(--out .*\), not in .*run"),
    "unknown --set key": ([*TRAIN, "--set", "data.max_agent=8", "--out", "{out}/run"],
                          r"unknown config key data\.max_agent \(did you mean data\.max_agents\?"
                          r"\); valid keys of section data: dataset, val_dataset, max_agents"),
    "unknown --set section": ([*TRAIN, "--set", "dat.max_agents=8", "--out", "{out}/run"],
                              r"unknown config key dat \(did you mean data\?\)"),
    "bad --set value": ([*TRAIN, "--set", "denoiser.epochs=many", "--out", "{out}/run"],
                        r"config denoiser\.epochs must be int"),
    "--set without =": ([*TRAIN, "--set", "seed", "--out", "{out}/run"],
                        r"must look like section\.key=value"),
    "inconsistent config": ([*TRAIN, "--set", "model.hidden=18", "--set", "model.heads=4",
                             "--out", "{out}/run"], r"hidden must be divisible by heads"),
    "missing --config": ([*TRAIN, "--config", "{in}/nope.yaml", "--out", "{out}/run"],
                         r"no such config file"),
    "invalid YAML": ([*TRAIN, "--config", "{in}/bad.yaml", "--out", "{out}/run"],
                     r"bad\.yaml: not valid YAML"),
    "--set text of YAML's own characters": (
        [*TRAIN, "--set", "data.delimiter=,", "--out", "{out}/run"],
        r"--set data\.delimiter=,: not valid YAML \(ParserError\); a text holding YAML's own "
        r"characters goes in quotes: --set 'data\.delimiter=\",\"'"),
    "--dataset path with a YAML comment sign": (
        ["train", "diffusion", *TINY, "--device", "cpu", "--no-progress", "--dataset",
         "{in}/no such #2", "--out", "{out}/run"],  # no --set data.dataset: given once
        r"no such #2: no such folder"),
    "--set text YAML reads as empty": (
        [*TRAIN, "--set", "data.delimiter=|", "--out", "{out}/run"],
        r"--set data\.delimiter=\|: YAML reads '\|' as the empty text; to mean those "
        r"characters, quote them: --set 'data\.delimiter=\"\|\"'"),
    "generator from a generator": (
        [*GEN, "--denoiser", "{run}/generator.safetensors", "--out", "{out}/run"],
        r"expected a denoiser checkpoint, got a generator"),
    "generator with no denoiser yet": ([*GEN, "--out", "{out}/run"],
                                       r"run/denoiser\.safetensors: the generator trains "
                                       r"through a denoiser and there is none in .*train it "
                                       r"there first.*or pass --denoiser FILE"),
    "agent roles with dropped agents": (
        [*GEN, "--denoiser", "{run}/denoiser.safetensors", "--out", "{out}/run", "--set",
         "model.agent_roles=3", "--set", "data.drop_agents=0.2"],
        r"model\.agent_roles reads each agent's slot .* data\.drop_agents 0"),
    "negative agent roles": (
        [*GEN, "--denoiser", "{run}/denoiser.safetensors", "--out", "{out}/run", "--set",
         "model.agent_roles=-1"], r"agent_roles must be >= 0"),
    # --- finetune
    "finetune from a denoiser": ([*FT, "--from", "{run}/denoiser.safetensors", "--out",
                                  "{out}/ft"], r"fine-tuning starts from a generator"),
    "finetune from nothing": ([*FT, "--from", "{in}/nope.safetensors", "--out", "{out}/ft"],
                              r"no such checkpoint"),
    "finetune from a run folder": ([*FT, "--from", "{run}", "--out", "{out}/ft"],
                                   r"--from .*: a folder, not a checkpoint file: pass "
                                   r".*generator\.safetensors"),
    "finetune from a resume state": ([*FT, "--from", "{run}/generator_last.pt", "--out",
                                      "{out}/ft"],
                                     r"a resume state \(pass it to --resume\), not a model; "
                                     r"the model is generator\.safetensors beside it"),
    "generator with another model than its denoiser": (
        [*GEN, "--set", "model.hidden=32", "--denoiser", "{run}/denoiser.safetensors", "--out",
         "{out}/g"],
        r"the generator's config differs from its denoiser checkpoint's \(model\.hidden: "
        r"\d+ there, 32 here\): train it with the denoiser's config"),
    "finetune resume the wrong stage": (
        [*FT, "--from", "{run}/generator.safetensors", "--out", "{out}/ft", "--resume",
         "{run}/generator_last.pt"],
        r"the state of a generator stage, not of finetune; pass finetune_last\.pt"),
    "finetune --out in /sys": ([*FT, "--from", "{run}/generator.safetensors", "--out",
                                "/sys/ft"], r"cannot write in /sys"),
    "control with a preset": (["finetune", "--method", "control", "--preset", "paper", "--from",
                               "{run}/generator.safetensors", "--out", "{out}/ft"],
                              r"the control takes no preset"),
    "finetune with another network size": (
        [*FT, "--from", "{run}/generator.safetensors", "--out", "{out}/ft", "--set",
         "model.samples=5"],
        r"model\.samples: fine-tuning keeps the network of the checkpoint it starts from "
        r"\(model\.samples = \d+ there, 5 asked\)"),
    "finetune with a pretraining stage's setting": (
        [*FT, "--from", "{run}/generator.safetensors", "--out", "{out}/ft", "--set",
         "generator.epochs=3"],
        r"generator\.epochs: fine-tuning does not read the pretraining stages' settings"),
    "finetune --set method against --method": (
        ["finetune", "--method", "control", "--from", "{run}/generator.safetensors", "--out",
         "{out}/ft", "--device", "cpu", "--set", "finetune.method=rlhf"],
        r"finetune\.method=rlhf contradicts --method control"),
    "finetune unknown key": ([*FT, "--from", "{run}/generator.safetensors", "--out", "{out}/ft",
                              "--set", "finetune.methd=rlhf"],
                             r"did you mean finetune\.method\?"),
    "control with RL settings": (
        ["finetune", "--method", "control", "--from", "{run}/generator.safetensors", "--out",
         "{out}/ft", "--set", "finetune.reward=set", "--set", "finetune.policy_weight=5"],
        r"finetune\.policy_weight, finetune\.reward: the control reads no RL setting .* "
        r"no effect; leave them out"),
    "rlhf-res with the set-aware reward": (
        [*FT, "--from", "{run}/generator.safetensors", "--out", "{out}/ft", "--set",
         "finetune.reward=set"], r"RLHF-ReS trains only .* use it with --method rlhf"),
    "equal budget and one of its keys": (
        [*FT, "--from", "{run}/generator.safetensors", "--out", "{out}/ft", "--equal-budget",
         "4", "--set", "finetune.max_minutes=6"],
        r"--equal-budget sets finetune\.max_minutes: leave it out of --set"),
    "equal budget of no minutes": (
        [*FT, "--from", "{run}/generator.safetensors", "--out", "{out}/ft", "--equal-budget",
         "-1"], r"must be a number of CPU minutes > 0"),
    # --- config show
    "config show unknown key": (["config", "show", "--set", "model.hiden=8"],
                                r"did you mean model\.hidden\?"),
    "config show missing file": (["config", "show", "--config", "{in}/nope.yaml"],
                                 r"no such config file"),
}  # fmt: skip


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    """Bad inputs, made once: broken datasets, random bytes, a legacy model checkpoint."""
    root = tmp_path_factory.mktemp("inputs")
    for name, text in {"cols": "0\t1\t1.0\n", "nan": "0\t1\tnan\t2.0\n", "empty": ""}.items():
        (root / name).mkdir()
        (root / name / "bad.txt").write_text(text)
    write_tracks(root / "nan" / "good.txt", straight_rows(24, agents=2))
    noise = random.Random(0).randbytes(2000)  # fixed: the same bytes on every machine
    (root / "rand.bin").write_bytes(noise)
    (root / "rand.safetensors").write_bytes(noise)
    # a pickle PROTO opcode for protocol 105: torch warns before it fails (seen in CI once
    # os.urandom happened to start with 0x80); the warning must not reach the user
    (root / "proto105.pt").write_bytes(b"\x80\x69" + noise)
    (root / "bad.yaml").write_text("data: [unclosed\n")
    torch.save({"format": "trajpref-checkpoint/1", "kind": "denoiser"}, root / "legacy.pt")
    torch.save(torch.zeros(3), root / "tensor.pt")
    return root


def _snapshot(*folders: Path) -> dict[str, tuple[int, int] | None]:
    """Every path under the folders: None for a folder, (size, modification time) for a file.
    (A folder's own time is left out: checking that a folder is writable creates and removes
    a probe file in it, which leaves nothing behind but touches the folder's time.)"""
    out = {}
    for folder in folders:
        for p in [folder, *folder.rglob("*")]:
            out[str(p)] = None if p.is_dir() else (p.stat().st_size, p.stat().st_mtime_ns)
    return out


@pytest.mark.parametrize("case", list(CASES))
def test_every_user_error_is_one_line_status_2_and_writes_nothing(
    case, tmp_path, capsys, monkeypatch, walks, tiny_run, inputs
):
    argv_template, pattern = CASES[case]
    out = tmp_path / "out"
    out.mkdir()
    (out / "afile").write_text("not a folder")
    for taken in ("taken.npz", "taken.png", "taken.json"):
        (out / taken).mkdir()
    places = {"walks": walks, "run": tiny_run, "in": inputs, "out": out}
    argv = [a.format(**places) for a in argv_template]
    monkeypatch.setenv("TRAJPREF_DATA", str(inputs))  # named datasets: a root without them
    before = _snapshot(tmp_path, tiny_run, inputs, walks)

    code = main(argv)
    stdout, stderr = capsys.readouterr()

    assert code == 2, stderr
    assert stdout == ""
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith("trajpref: error: ")
    assert re.search(pattern, lines[0]), lines[0]
    assert _snapshot(tmp_path, tiny_run, inputs, walks) == before
    assert not Path("/sys/trajpref-run").exists() and not Path("/sys/ft").exists()


def test_the_table_is_long_enough():
    assert len(CASES) >= 40


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_an_unwritable_output_folder(tmp_path, capsys, walks):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        code = main(["evaluate", "--dataset", str(walks), "--out", str(locked / "e.json")])
    finally:
        locked.chmod(0o700)
    err = capsys.readouterr().err
    assert code == 2 and re.fullmatch(r"trajpref: error: --out .*: cannot write in .*\n", err)
    assert list(locked.iterdir()) == []


def test_an_os_error_is_one_line_too(capsys, monkeypatch, walks):
    """A file that cannot be read (permissions, a vanished disk) is not a traceback either."""

    def unreadable(*args, **kwargs):
        raise PermissionError(13, "Permission denied", "/data/eth/test/a.txt")

    monkeypatch.setattr(cli, "load_dataset", unreadable)
    code = main(["data", "stats", "--dataset", str(walks)])
    err = capsys.readouterr().err
    assert code == 2 and err == "trajpref: error: /data/eth/test/a.txt: Permission denied\n"


def test_a_published_models_repository_path_names_it_outside_the_repository(
    capsys, monkeypatch, tmp_path
):
    """`--from models/zara1/generator.safetensors` (the README's path) where there is no such
    file: the error names the published name, which works in any folder."""
    from trajpref.models import zoo

    if not zoo.published():
        pytest.skip("the package was built without its models")
    name = next(n for n in zoo.published() if n.endswith("/generator"))
    monkeypatch.chdir(tmp_path)
    path = f"models/{name}.safetensors"
    for argv in (["finetune", "--method", "rlhf", "--from", path, "--out", "ft"],
                 ["evaluate", "--dataset", "eth", "--model", path],
                 ["evaluate", "--dataset", "eth", "--model", "cv", "--scorer", path]):  # fmt: skip
        flag = argv[argv.index(path) - 1]
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err == (f"trajpref: error: {flag} {path}: no such checkpoint here; the published "
                       f"model is named {name} ({flag} {name} works in any folder)\n")  # fmt: skip
    assert list(tmp_path.iterdir()) == []


def test_a_resume_with_nothing_left_to_train_is_a_note_and_status_0(
    capsys, tmp_path, walks, tiny_run
):
    """Batch walkthrough 2026-12-06: a job requeued after its run had finished (``--resume``
    of a state whose epochs are done) failed with status 2; it succeeds now, with the note on
    stderr, nothing on stdout and nothing written. From Python it is still a ConfigError."""
    from trajpref.errors import ConfigError
    from trajpref.train.run import NothingLeftToTrain

    argv = [a.format(walks=walks) for a in TRAIN]
    argv += ["--set", "denoiser.epochs=1", "--out", str(tiny_run), "--resume",
             str(tiny_run / "denoiser_last.pt")]  # fmt: skip
    before = _snapshot(tiny_run, walks)
    code = main(argv)
    out, err = capsys.readouterr()
    assert (code, out) == (0, ""), err
    assert re.fullmatch(r"trajpref: note: --resume .*denoiser_last\.pt: the state has finished "
                        r"\d+ epochs and this run has 1: nothing left to train \(raise "
                        r"denoiser\.epochs to train longer\)\n", err), err  # fmt: skip
    assert _snapshot(tiny_run, walks) == before
    assert issubclass(NothingLeftToTrain, ConfigError)
