"""Write the model zoo's index and model cards from the published checkpoints and the results.

    python benchmarks/zoo_index.py           # writes models/index.json, models/<D>/<name>.md
                                             # and the README's listing (<!-- models -->)
    python benchmarks/zoo_index.py --check   # exit 1 if they are not what this would write,
                                             # or a card's test row names none of its file's
                                             # model_hash (``card_row``)

The installed package has no ``benchmarks/results/``, so everything ``trajpref models`` shows
is copied here into files that ship with the weights (``models/`` links to the package's
``src/trajpref/zoo/``): per model its kind, method, the data it was trained on, the training
machine and minutes (per stage), the command that trains it again, and its test row (minADE20
/ minFDE20 from ``benchmarks/results/*.json``, the row that names the file's ``model_hash``;
a denoiser's row is its full 100-step sampler).
Run it after publishing a model (benchmarks/pretrain.py, benchmarks/finetune.py --publish).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path
from typing import Any

from row_hashes import timed_weights

from trajpref.config import GENERATOR_ONLY, load_config, resolve_config, to_dict
from trajpref.data.registry import SPECS
from trajpref.io import dotted
from trajpref.models import checkpoint as ckpt
from trajpref.models import zoo
from trajpref.models.timing import PACE_LIMIT
from trajpref.results import START_SUFFIXES, read_rows

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"

DATA = {
    **{
        d: f"ETH/UCY `{d}` fold (Social-GAN leave-one-out): trained on the other four scenes' "
        f"train files, chosen on `{d}`'s val split, tested on `{d}`'s test split"
        for d in ("eth", "hotel", "univ", "zara1", "zara2")
    },
    "robo": "Trained on `robo-sim` (our simulator of the paper's Robo scenario; no public "
    "Robo training split exists), its epoch chosen on the official Robo val split (real "
    "robots), tested on the paper's official Robo test set",
    "robo-mix": "Trained on `robo-sim` plus 15 of the 19 recordings of the official Robo val "
    "split (repeated to a third of the training scenes), chosen on the other 4 recordings, "
    "tested on the paper's official Robo test set (docs/data.md, robo-mix)",
    "sdd": "Stanford Drone Dataset, TrajNet split (MART's `sdd_{train,test}.pkl` windows; "
    "MoFlow reads files of that name, probably the same windows, under another protocol; "
    "LED's SDD number is second-hand: docs/data.md, 'SDD and its peers'): trained on its "
    "train split minus 10 % of the scenes held out for validation, tested on its test split",
    "nba": "NBA rebound tracking (SocialVAE's split, 8 + 12 frames at 0.12 s: 0.96 s observed, "
    "1.44 s predicted; metres): trained on its train files minus 10 % held out for validation, "
    "tested on its test files; not LED's 10 + 20 frame split (2 s + 4 s), so not comparable "
    "with LED's NBA numbers",
}
"""What each dataset's models were trained and tested on."""

LIMITS = {
    "eth": "eth's test walkers are faster than any training scene: a quarter (89 of 364 "
    "agent-windows) move above 2 m/s, and they carried 35-44 % of the minFDE20 error in the "
    "breakdowns on file (`benchmarks/results/meta/speed_breakdown_eth*.json`, generators of "
    "2026-11-22 to 2026-11-28: 44 % for the 0.759-minFDE20 default of 2026-11-25, 38 % for "
    "the 0.672 one of 2026-11-28; today's default has none on file), so the default model is "
    "far from the paper's LED row (0.33 / 0.60); validation (the other scenes) does not see "
    "that shift.",
    "eth/generator-pace": "Labelled: trained on a second copy of its training files read every "
    "5/3 frame steps (`data.extra_time_step`), the pace of eth's test file as its provenance "
    "documents it (docs/data.md). That is knowledge of the test file the other defaults do "
    "not use, so this is a variant beside eth's default, never the default; eth's validation "
    "split cannot choose it (docs/pretraining.md, 'eth at two paces').",
    "sdd/generator": "Since 2026-12-06 it trains every one of its 20 samples "
    "(`generator.reg_weight` 0.005, Eq. 4 at a light weight beside best-of-K): its "
    "predecessor's sample 14 was untrained noise, with jumps of up to about 400 px in one "
    "step (docs/pretraining.md, 'SDD: a lighter sample-training term as the defect fix'). "
    "That was judged by non-inferiority on validation (+0.7 % minFDE20, -0.2 % minADE20 over "
    "three seeds); on the test split minFDE20 went 11.81 -> 11.99 px (+1.5 %) and minADE20 "
    "7.43 -> 7.39 px, 0.33 px above LED's published 11.66.",
    "zara1/generator": "The CPU default (160 generator epochs without denoising steps, dropout "
    "0.2; its best validation epoch is under Training above) is 0.04 m short of LED's own "
    "minFDE20 (0.18 / 0.26); the "
    "GPU-trained `generator-long` (160 epochs with the tau = 5 steps; its weights left the "
    "tree on 2026-11-28, `git show 793f59a:src/trajpref/zoo/zara1/generator-long.safetensors`) "
    "is no better on the test split (docs/pretraining.md).",
    "robo": "Trained on our simulator only (docs/robo_sim.md says how it differs from the real "
    "robots).",
    "robo/generator": "It expects scenes of at most 3 robots listed as leader, "
    "follower, approacher (`model.agent_roles`): listed in another order it is 3-5x worse, "
    "about constant velocity (`benchmarks/robo_order.py`); for robots whose roles are unknown "
    "use the generator without roles (test 0.269 / 0.387), which is in git only and loads "
    "with the published `robo/denoiser.safetensors` (the same hash) beside it: `mkdir norole "
    "&& git show 4450d00:src/trajpref/zoo/robo/generator.safetensors > "
    "norole/generator.safetensors && cp src/trajpref/zoo/robo/denoiser.safetensors norole/`, "
    "then `load_predictor('norole/generator.safetensors')`. "
    "The GPU-trained `generator-long` of "
    "2026-11-22 left the tree on 2026-11-29 (`git show "
    "96c7b75:src/trajpref/zoo/robo/generator-long.safetensors`).",
    "robo-mix/generator": "Like `robo/generator`, it expects at most 3 robots in their fixed "
    "order (`model.agent_roles`; 3-5x worse in another order); without roles (test 0.261 / "
    "0.359), in git only, with the published `robo-mix/denoiser.safetensors` (the same hash) "
    "copied beside it: `mkdir norole-mix && git show "
    "4450d00:src/trajpref/zoo/robo-mix/generator.safetensors > norole-mix/generator.safetensors "
    "&& cp src/trajpref/zoo/robo-mix/denoiser.safetensors norole-mix/`.",
    "robo-mix": "One seed. Its held-out validation (4 real recordings, 135 windows) moves by "
    "about 0.02 m between epochs, too little data to rank close candidates (docs/pretraining.md). "
    "Its test row is better than the sim-only `robo/generator`'s and 0.009 m below the "
    "paper's LED minFDE20 (0.35); it is published beside the sim-only default, which trains on "
    "our simulator alone.",
    "nba": "A 6-epoch denoiser and 40 generator epochs without denoising steps over 203,511 "
    "windows, to fit the 45-minute CPU budget; twice the generator epochs did not improve "
    "validation (docs/pretraining.md). Our 8 + 12 split is not LED's 10 + 20, so LED's NBA "
    "numbers are not comparable; its minADE20 / minFDE20 average over all 11 agents of a "
    "window, the ball included.",
    "nba/generator": "It reads each agent's positions in metres with x along the court's "
    "94 ft (28.65 m) length and y across its 50 ft (15.24 m) width, as the rebound files have "
    "them (any origin: a shifted scene gets the same futures, shifted), and `agent_type` (1 "
    "the ball, 0 a player); no team, no court or basket position. Trained without rotation "
    "(`data.rotate: false`, mirrored only), it reads a court turned 90 degrees (x and y "
    "swapped) with no error or warning and predicts it worse: minADE20 0.210 -> 0.330 m "
    "(+57 %) on 50 evenly spaced test scenes (2026-12-06). Over the players alone "
    "(`trajpref evaluate --dataset nba --model nba/generator --agents persons`, as SocialVAE "
    "counts its split) it is 0.180 / 0.322 m (0.59 / 1.06 ft), joint 0.420 / 0.939.",
    "nba/denoiser": "As a scorer it reads the court's axes as its generator does (x along the "
    "94 ft length, metres, any origin, `agent_type` 1 for the ball; no team, no court or "
    "basket position) and was trained without rotation: with x and y swapped, the best of "
    "`nba/generator`'s 20 samples by `rank_samples` changed in 50 of 50 evenly spaced test "
    "scenes (2026-12-06), with no warning.",
    "denoiser": "As a scorer (`--scorer`, `TrajectoryScorer`) see docs/score.md: its ranking "
    "matches the paper's top-5 recall on zara1, is at chance on eth.",
}
"""Known limits, by dataset, by model name and by kind (all that apply are listed); the
generated ones (``generated_limits``) follow them."""

LED_GAP = {"robo/generator": "robo"}
"""Models whose card states its distance to the seed paper's LED row (paper_tables.json),
computed from its test row: the name -> the paper's dataset."""

STAGE_SECTIONS = {"denoiser": ("data", "model", "diffusion", "denoiser"),
                  "generator": ("data", "model", "diffusion", "generator")}  # fmt: skip
"""Config sections that shape each kind's training (the others are not its settings)."""


def config_option(dataset: str) -> str:
    """The ``--config`` of a card's training command: the shipped config by its name
    (``--config zara1``), which an installed package finds as the repository finds
    ``configs/zara1.yaml`` (the same file: ``configs/`` links to the package's)."""
    if resolve_config(dataset).resolve() != (ROOT / "configs" / f"{dataset}.yaml").resolve():
        raise SystemExit(f"--config {dataset} is not configs/{dataset}.yaml")
    return f"--config {dataset}"


SOURCE_NOTE = ("The `benchmarks/` scripts and results, the `docs/` pages and the `git show` "
               "commands this card cites are in the source repository (a checkout of "
               "trajpref), not in the installed package; its `trajpref` commands work in "
               "either.")  # fmt: skip
"""The card's line that places what it cites, for a reader of ``trajpref models NAME`` in an
installed package."""


def overrides(dataset: str, kind: str, config: dict[str, Any]) -> list[str]:
    """``--set`` values that turn configs/<dataset>.yaml into the checkpoint's config."""
    base = dotted(to_dict(load_config(ROOT / "configs" / f"{dataset}.yaml")))
    got = dotted(config)
    skip = {f"model.{k}" for k in GENERATOR_ONLY} if kind == "denoiser" else set()
    keys = [k for k in got if k.split(".")[0] in STAGE_SECTIONS[kind] and base.get(k) != got[k]
            and k not in skip]  # fmt: skip
    return [f"{k}={_scalar(got[k])}" for k in keys]


def _scalar(value: Any) -> str:
    """A config value as ``--set`` reads it back: YAML's null, true and false, quoted strings."""
    return json.dumps(value) if value is None or isinstance(value, bool | str) else str(value)


def trained_config(config: dict[str, Any], changes: list[dict[str, Any]]) -> dict[str, Any]:
    """The config a generator was trained with: its file's config with the sampling changes
    made after training (``checkpoint.set_generator_setting`` and ``publish_variant``, logged
    in ``meta["changes"]``) undone."""
    out = json.loads(json.dumps(config))
    for change in reversed(changes):
        for name in ckpt.POST_HOC_SETTINGS:
            if name in change and "previous" in change:
                out["model"][name] = change["previous"]
            elif name == "stochastic_steps" and name in change:  # logged before "previous"
                out["model"][name] = not change[name]
    return out


SETTING_FLAGS = {
    "max_speed": "--max-speed",
    "spread_scale": "--spread-scale",
    "max_log_sigma": "--max-log-sigma",
    "neighbour_radius": "--neighbour-radius",
}
"""The sampling option of each of ``checkpoint.POST_HOC_SETTINGS`` (``stochastic_steps``:
``--stochastic`` or ``--deterministic``)."""


def setting_flag(name: str, value: Any) -> str:
    """The ``trajpref evaluate|predict|plot`` option that samples with ``model.<name>`` at
    ``value`` (None: ``none``, which --max-log-sigma and --neighbour-radius take)."""
    if name == "stochastic_steps":
        return "--stochastic" if value else "--deterministic"
    return f"{SETTING_FLAGS[name]} {'none' if value is None else value}"


def after_training(
    published: dict[str, Any], trained: dict[str, Any], changes: list[dict[str, Any]], rebuilt: str
) -> dict[str, Any] | None:
    """The sampling settings (``checkpoint.POST_HOC_SETTINGS``) a published generator took
    after training: each whose value in the file (``published``, its config) differs from the
    one its training command gives (``trained``, ``trained_config``), with that value, the
    option that samples with it, and its logged notes; and the call that writes them all into
    the rebuilt file ``rebuilt`` (a path). None when there is none."""
    settings = []
    for name in ckpt.POST_HOC_SETTINGS:
        value, before = published["model"].get(name), trained["model"].get(name)
        if value == before:
            continue
        notes = "; ".join(change_note(c) for c in changes if name in c)
        settings.append({"setting": name, "value": value, "trained": before,
                         "flag": setting_flag(name, value), "notes": notes})  # fmt: skip
    if not settings:
        return None
    calls = "; ".join(f"s({rebuilt!r}, {s['setting']!r}, {s['value']!r}, 'as published')"
                      for s in settings)  # fmt: skip
    write = (
        f'python -c "from trajpref.models.checkpoint import set_generator_setting as s; {calls}"'
    )
    return {"settings": settings, "write": write}


def _after_training_lines(after: dict[str, Any] | None) -> list[str]:
    """The card's lines after its training commands: the sampling settings written into the
    published file after training, each with its option, and the call that writes them in."""
    if not after:
        return []
    lines = ["# set after training, same weights (in the published file; sample the rebuilt "
             "file with these options, or write them in with the line below):"]  # fmt: skip
    for s in after["settings"]:
        lines.append(f"#   model.{s['setting']} = {_scalar(s['value'])} (trained with "
                     f"{_scalar(s['trained'])}): {s['flag']} ({s['notes']})")  # fmt: skip
    return [*lines, after["write"]]


def change_note(change: dict[str, Any]) -> str:
    """A logged settings change's note, with its date in front when the file recorded one
    (``checkpoint.set_generator_setting`` stamps it since 2026-11-27) and the note lacks it."""
    date, note = change.get("date"), change["note"]
    return f"{date}: {note}" if date and date not in note else note


def machine_short(machine: str | None) -> str:
    if not machine:
        return "-"
    gpu = re.search(r"(H100|H200|A100|V100|RTX \w+)", machine)
    if gpu:
        return f"GPU ({gpu.group(1)})"
    cores = re.search(r"(\d+) CPU cores", machine)
    return f"CPU ({cores.group(1)} cores)" if cores else machine[:24]


def thread_prefix(machine: str | None) -> str:
    """``OMP_NUM_THREADS=N `` for a CPU run whose machine string records its thread count: a
    seed repeats its run exactly only at the same count (a two-thread retrain of Robo's
    one-thread seed 1 ended 4 % away, docs/pretraining.md), so the card's command says it."""
    if not machine or machine_short(machine).startswith("GPU"):
        return ""
    threads = re.search(r"(\d+) threads?\b", machine)
    return f"OMP_NUM_THREADS={threads.group(1)} " if threads else ""


def _zoo_file(checkpoint: str | None) -> str | None:
    """A result row's checkpoint path -> zoo name (results older than the safetensors
    conversion name the ``.pt`` file)."""
    if not checkpoint or not checkpoint.startswith("models/"):
        return None
    return str(Path(checkpoint).with_suffix("")).removeprefix("models/")


def _meta(dataset: str, variant: str | None) -> dict[str, Any]:
    name = f"pretrained_{dataset}{'_' + variant if variant else ''}.json"
    path = RESULTS / "meta" / name
    return json.loads(path.read_text()) if path.is_file() else {}


def _newest(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The newest of ``rows`` by date (ties: the later row)."""
    out = rows[0]
    for r in rows[1:]:
        if (r.get("date") or "") >= (out.get("date") or ""):
            out = r
    return out


def card_row(name: str, candidates: list[dict[str, Any]],
             digest: str | None) -> tuple[dict[str, Any] | None, str | None]:  # fmt: skip
    """The test row a card shows among ``candidates`` (the rows of its file and method) and,
    when that row cannot be shown to have measured the file, why: the newest row whose
    ``model_hash`` is the file's ``digest`` (``checkpoint.model_hash`` for the card's sampler);
    without one, the newest row of all, with a problem line. A row without a digest whose
    file has since been replaced (the ``.pt`` files became ``.safetensors`` on 2026-11-23)
    must not stand beside a re-measurement that names the file's digest, nor pass unnoticed
    where there is none."""
    if not candidates:
        return None, None
    matching = [r for r in candidates if digest is not None and r.get("model_hash") == digest]
    if matching:
        return _newest(matching), None
    row = _newest(candidates)
    what = ("names no model_hash" if row.get("model_hash") is None
            else f"measured {row['model_hash']}")  # fmt: skip
    return row, (f"{name}: its test row ({row['method']}, {row['date']}, "
                 f"{row.get('checkpoint')}) {what}, and no row names the file's {digest}: "
                 "measure the file again")  # fmt: skip


def newest_rows(rows: list[dict[str, Any]]) -> dict[tuple, dict[str, Any]]:
    """(zoo name, method) -> the newest row naming that file with that method: other studies
    (the score's, the selection's) keep a copy of the row they started from, which must not
    stand for the file once it has been re-measured (ties: the later row)."""
    out: dict[tuple, dict[str, Any]] = {}
    for r in rows:
        key = (_zoo_file(r.get("checkpoint")), r["method"])
        if key not in out or (r.get("date") or "") >= (out[key].get("date") or ""):
            out[key] = r
    return out


def tuned_row(rows: list[dict[str, Any]], dataset: str, stem: str,
              from_today: bool) -> dict[str, Any] | None:  # fmt: skip
    """The seed-0 test row of a published fine-tuned generator ``<dataset>/<stem>``: method
    ``stem`` when it started from today's default generator (``from_today``), else ``stem``
    with the suffix of the start it was trained from, which ``benchmarks/retire_start.py``
    gave its row when that start was replaced (a later run from today's default may hold the
    plain name)."""
    names = {stem} if from_today else {stem + s for s in START_SUFFIXES}
    return next((r for r in rows if r["dataset"] == dataset and r["method"] in names
                 and r["seed"] == 0), None)  # fmt: skip


PORTABLE_DATA_ROOT = "../shared/data"
"""The data root a card's command names: the Makefile's default, relative to the checkout, as
the repository's documented commands give it."""

_DATA_ROOT = re.compile(r"(--data-root[ =])(/\S*)")


def portable_command(command: str | None) -> str | None:
    """A results row's command as a card shows it: an absolute ``--data-root`` (the machine
    that ran it) becomes ``PORTABLE_DATA_ROOT``; the row itself keeps what was run."""
    if command is None:
        return None
    return _DATA_ROOT.sub(lambda m: m.group(1) + PORTABLE_DATA_ROOT, command)


def _test_row(row: dict[str, Any]) -> dict[str, Any]:
    keys = ("split", "samples", "seed", "min_ade", "min_fde", "joint_min_ade", "joint_min_fde",
            "date", "machine", "command")  # fmt: skip
    out = {k: row.get(k) for k in keys}
    out["command"] = portable_command(out["command"])
    out["protocol"] = row.get("protocol", "all")  # the windows counted (docs/data.md)
    out["method"] = row["method"]
    return out


def describe(name: str, path: Path, rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The index entry of one published file."""
    dataset, stem = name.split("/")
    head = zoo.header(path)
    kind, meta = head["kind"], head.get("meta") or {}
    # a card's test row is the default protocol's (``all``): the same file and method also
    # has ``sgan`` rows, often the newer ones
    rows = [r for r in rows if r.get("protocol", "all") == "all"]
    den_threads = None  # where a generator card's denoiser command takes its threads from
    entry: dict[str, Any] = {"name": name, "dataset": dataset, "kind": kind,
                             "file": f"{dataset}/{path.name}", "hash": head["hash"]}  # fmt: skip
    spec = SPECS.get(dataset)
    cfg = to_dict(ckpt.config_of(head))  # resolved (a file older than a default keeps its own)
    entry["data"] = {
        "description": DATA.get(dataset, f"`{dataset}`"),
        "trained_on": meta.get("dataset", cfg["data"]["dataset"]),
        "tested_on": dataset,
        "units": spec.units if spec else None,
        "frame_interval": spec.frame_interval if spec else None,
        "t_hist": cfg["model"]["t_hist"],
        "t_fut": cfg["model"]["t_fut"],
        "scale": head.get("scale"),
    }
    variant = stem.split("-", 1)[1] if "-" in stem else None
    changes = meta.get("changes") or []
    if kind == "generator":
        entry["sampling"] = {"tau": cfg["model"]["tau"],
                             "stochastic_steps": cfg["model"]["stochastic_steps"],
                             "agent_frame": cfg["model"].get("agent_frame", "scene"),
                             "max_speed": cfg["model"].get("max_speed", 0.0),
                             "history_encoder": cfg["model"].get("history_encoder", "mlp"),
                             "dropout": cfg["model"].get("generator_dropout", 0.0),
                             **({"encoder_dropout": e} if (e := cfg["model"].get("encoder_dropout"))
                                else {}),
                             **({"context_agents": True}
                                if cfg["model"].get("context_agents") else {}),
                             "flip": cfg["data"].get("flip", False),
                             **({"reverse": True} if cfg["data"].get("reverse") else {}),
                             **({"future_rank": r} if (r := cfg["model"].get("future_rank"))
                                else {}),
                             "spread_scale": cfg["model"].get("spread_scale", 1.0),
                             **({"max_log_sigma": m} if (m := cfg["model"].get("max_log_sigma"))
                                is not None else {}),
                             "ema_epochs": meta.get("ema_epochs"),
                             "changes": changes}  # fmt: skip
        published = cfg  # the file's own sampling settings
        cfg = trained_config(cfg, changes)  # the training command reproduces the run
        ref = head.get("denoiser_ref") or {}
        entry["denoiser"] = f"{dataset}/{Path(ref['path']).stem}" if ref else None
        entry["sampler"] = "leapfrog"
        if "method" in meta:  # a fine-tuned generator (benchmarks/finetune.py --publish)
            entry["method"] = meta["method"]
            today = zoo.header(path.parent / f"generator{ckpt.SUFFIX}").get("hash")
            from_today = meta.get("from") == today
            row, start = tuned_row(rows, dataset, stem, from_today), f"{dataset}/generator"
            row, unverified = card_row(name, [row] if row else [],
                                       ckpt.header_model_hash(head, "leapfrog"))  # fmt: skip
            run = _meta(dataset, None)
            machine, machine_from = (row["machine"] if row else None), "test row"
            train_cmd = []
            if not from_today:  # fine-tuned from a default since replaced
                suffix = row["method"].removeprefix(stem) if row else ""
                kept = next((r for r in rows if r["dataset"] == dataset
                             and r["method"] == f"pretrained{suffix}"), None)  # fmt: skip
                where = f" ({kept['checkpoint']})" if kept and suffix else ""
                train_cmd.append(f"# from {dataset}'s default generator of its day, weights hash "
                                 f"{meta.get('from')}, since replaced{where}:")  # fmt: skip
                start = "START.safetensors"
            train_cmd.append(f"trajpref finetune --method {meta['method']} --from {start} "
                             f"--out runs/{dataset}-{stem}")  # fmt: skip
            minutes = {"finetune": round(meta["train_seconds"] / 60, 1)}
            rebuilt = f"runs/{dataset}-{stem}/finetune{ckpt.SUFFIX}"
        else:
            entry["method"] = "pretrained" + (f"-{variant}" if variant else "")
            row, unverified = card_row(name, [
                r for r in rows if (_zoo_file(r.get("checkpoint")), r["method"])
                == (name, entry["method"])], ckpt.header_model_hash(head, "leapfrog"))  # fmt: skip
            run = _meta(dataset, variant)
            machine = run.get("train_machine") or run.get("trained_on")
            machine_from = "training" if machine else "test row"
            machine = machine or (row or {}).get("machine")
            out = f"runs/{dataset}" + (f"-{variant}" if variant else "")
            rebuilt = f"{out}/generator{ckpt.SUFFIX}"
            den = ""
            if variant and entry["denoiser"] == f"{dataset}/denoiser":
                den = f" --denoiser {dataset}/denoiser"
            gpu = " --device cuda" if run.get("train_machine") else ""
            sets = "".join(f" --set {s}" for s in overrides(dataset, kind, cfg))
            seed = f" --seed {cfg['seed']}" if cfg.get("seed") else ""  # the run's own seed
            threads = "" if gpu else thread_prefix(machine)
            train_cmd = [f"{threads}trajpref train generator {config_option(dataset)} "
                         f"--out {out}{den}{seed}{sets}{gpu}"]  # fmt: skip
            if not den:  # trained with its own denoiser, in the same run folder
                # the denoiser's own settings: a data flag adopted for the generator stage only
                # (data.flip, data.reverse) is off in the published denoiser's file
                den_file = path.parent / f"{Path(ref['path']).stem}.safetensors" if ref else None
                den_head = (zoo.header(den_file) if den_file is not None and den_file.is_file()
                            else None)  # fmt: skip
                den_cfg = to_dict(ckpt.config_of(den_head)) if den_head else cfg
                den_digest = ckpt.header_model_hash(den_head, "full") if den_head else None
                den_machine, den_from = denoiser_machine((den_head or {}).get("meta") or {},
                                                         rows, dataset, variant,
                                                         den_digest)  # fmt: skip
                train_cmd.insert(0, denoiser_command(dataset, out, den_cfg, den_machine))
                if den_from != "training" and thread_prefix(den_machine):
                    den_threads = den_from
            ref = head.get("weights_ref")
            if ref:  # a settings-only variant: its base's run, then the settings
                base = f"{dataset}/{Path(ref['path']).stem}"
                train_cmd = [
                    f"# the weights of {base} (its training commands), then, after training:",
                    *(f"#   model.{k} = {c[k]:.4g} ({change_note(c)})" if isinstance(c[k], float)
                      else f"#   model.{k} = {c[k]} ({change_note(c)})"
                      for c in meta.get("changes", [])
                      for k in ckpt.POST_HOC_SETTINGS if k in c),
                ]  # fmt: skip
                entry["weights_of"] = base
                rebuilt = None  # its lines above name the settings already
            seconds = (run.get("stage_seconds") or {}).get("generator") or meta.get("train_seconds")
            minutes = {"generator": round(seconds / 60, 1) if seconds else None}
    else:
        entry["sampler"] = "full"
        entry["method"] = "denoiser" + (f"-{variant}" if variant else "")
        digest = ckpt.header_model_hash(head, "full")
        row, unverified = card_row(name, _full_sampler_rows(rows, dataset, variant), digest)
        run = _meta(dataset, variant)
        machine, machine_from = denoiser_machine(meta, rows, dataset, variant, digest)
        out = f"runs/{dataset}" + (f"-{variant}" if variant else "")
        train_cmd = [denoiser_command(dataset, out, cfg, machine)]
        seconds = (run.get("stage_seconds") or {}).get("denoiser") or meta.get("train_seconds")
        minutes = {"denoiser": round(seconds / 60, 1) if seconds else None}
    entry["train"] = {
        "machine": machine,
        "machine_from": machine_from,
        **({"denoiser_threads_from": den_threads} if den_threads else {}),
        "machine_short": machine_short(machine),
        "minutes": minutes,
        "estimate": None if variant else _cost_estimate(dataset, kind, cfg),
        "epochs": meta.get("epoch"),
        "validation": meta.get("val"),
        "commands": train_cmd,
    }
    if kind == "generator" and rebuilt:
        entry["train"]["after_training"] = after_training(published, cfg, changes, rebuilt)
    entry["test"] = _test_row(row) if row else None
    full_row = any(r["method"] == "full-sampler" and r["dataset"] == dataset
                   and r.get("split") == "test" for r in rows)  # fmt: skip
    entry["limits"] = [LIMITS[k] for k in (dataset, name, kind) if k in LIMITS]
    entry["limits"] += generated_limits(name, kind, entry["test"], full_row, head.get("scale"))
    entry["card"] = f"{dataset}/{stem}.md"
    if unverified:  # not written to the index: build() reports it, --check fails on it
        entry["_unverified"] = unverified
    return entry


def _cost_estimate(dataset: str, kind: str, cfg: dict[str, Any]) -> dict[str, Any] | None:
    """The training minutes ``benchmarks/train_cost.py`` estimated for the fold's default
    config alone on this CPU, when that record measured the epochs this file was trained
    with (a stale record, from before a config change, is not quoted)."""
    path = RESULTS / "meta" / "train_cost.json"
    if not path.exists():
        return None
    record = json.loads(path.read_text())
    cost = record.get("datasets", {}).get(dataset)
    if not cost:
        return None
    stages = ("denoiser", "generator") if kind == "generator" else ("denoiser",)
    epochs = {"denoiser": cfg["denoiser"]["epochs"], "generator": cfg["generator"]["epochs"]}
    if any(cost.get(k, {}).get("epochs") != epochs[k] for k in stages):
        return None
    return {"date": cost.get("date") or record.get("date"),
            "machine": cost.get("machine") or record.get("machine"),
            "minutes": {k: cost[k]["minutes"] for k in stages}}  # fmt: skip


def _full_sampler_rows(rows: list[dict[str, Any]], dataset: str,
                       variant: str | None) -> list[dict[str, Any]]:  # fmt: skip
    """The full-sampler rows of the generator file that references a denoiser (the run that
    trained it, and any re-measurement of it)."""
    name = f"{dataset}/generator" + (f"-{variant}" if variant else "")
    return [r for r in rows if r["method"] == "full-sampler" and r["dataset"] == dataset
            and _zoo_file(r.get("checkpoint")) == name]  # fmt: skip


MACHINE_FROM = {
    "training": "On {machine}",
    "test row": "No training record names the machine; the one that evaluated its test row "
    "(below) was {machine}",
    "another row": "No training record names the machine, and it has no test row of its own; "
    "the one that evaluated the `pretrained` row of {dataset} (its generator's) was {machine}",
}
"""Where a card's machine comes from: a training record (``trained_on``, ``train_machine``,
a checkpoint's ``meta.machine``), the run that evaluated its test row, or another row of its
dataset; the last two say so on the card."""


def denoiser_machine(meta: dict[str, Any], rows: list[dict[str, Any]], dataset: str,
                     variant: str | None,
                     digest: str | None = None) -> tuple[str | None, str]:  # fmt: skip
    """A published denoiser's machine and where it comes from (a ``MACHINE_FROM`` key): its
    checkpoint's own record of the training process (``meta.machine``; no published denoiser
    has one today: each was trained before the field, or reused by a later run), else the
    machine of its full-sampler test row (the one its card shows: ``card_row`` with the
    denoiser's full-sampler ``digest``), else that of its dataset's ``pretrained`` row."""
    if meta.get("machine"):
        return meta["machine"], "training"
    row, _ = card_row("", _full_sampler_rows(rows, dataset, variant), digest)
    if row is not None:
        return row.get("machine"), "test row"
    return _any_machine(rows, dataset, variant), "another row"


def denoiser_command(dataset: str, out: str, cfg: dict[str, Any], machine: str | None) -> str:
    """The command that trains a published denoiser again: its config's ``--set`` values,
    the thread count of ``machine`` in front as the generator commands have it (a seed
    repeats its run exactly only at the same count)."""
    sets = "".join(f" --set {s}" for s in overrides(dataset, "denoiser", cfg))
    return (
        f"{thread_prefix(machine)}trajpref train diffusion {config_option(dataset)} "
        f"--out {out}{sets}"
    )


def _any_machine(rows: list[dict[str, Any]], dataset: str, variant: str | None) -> str | None:
    """The machine of the generator's ``pretrained`` row that its card shows (the newest row
    of that file), else of any ``pretrained`` row of the dataset."""
    suffix = f"-{variant}" if variant else ""
    method = f"pretrained{suffix}"
    row = newest_rows(rows).get((f"{dataset}/generator{suffix}", method)) or next(
        (r for r in rows if r["dataset"] == dataset and r["method"] == method), None
    )
    return row["machine"] if row else None


def speed_note(speed: dict[str, Any], dataset: str, changed: bool = False) -> str:
    """A denoiser's cost as a predictor, from ``benchmarks/speed.py``'s record (``speed``):
    the range of full-sampler / leapfrog ratios over the published generators it timed, and
    the ratio for the dataset's default generator where it timed one (``changed``: that
    generator's file has changed since, ``row_hashes.timed_weights``, and the note says the
    ratio is the predecessor's); "" without a record."""
    timed = speed.get("models") or {}
    if not timed:
        return ""
    ratios = [m["full_over_leapfrog"] for m in timed.values()]
    own = timed.get(f"{dataset}/generator")
    mine = (f", {own['full_over_leapfrog']:.1f}x beside `{dataset}/generator`" if own
            else "")  # fmt: skip
    if own and changed:
        mine += " as it was then (its file has changed since; the README's table marks it)"
    return (f"As a predictor it runs the full 100-step sampler, which took "
            f"{min(ratios):.1f}-{max(ratios):.1f}x the time per scene of each published "
            f"generator's leapfrog in `benchmarks/results/meta/speed.json` "
            f"({speed.get('date')}, the README's speed table){mine}.")  # fmt: skip


def led_gap(row: dict[str, Any], led: list[float]) -> str:
    """The sentence that places a test row against the seed paper's LED row ``led`` (minADE20,
    minFDE20), computed from the row (a hand-written distance went stale when the row
    changed)."""

    def side(ours: float, theirs: float) -> str:
        gap = round(ours - theirs, 3)
        if gap == 0:
            return "level with"
        return f"{abs(gap):.3f} m {'above' if gap > 0 else 'below'}"

    return (
        f"Its test minFDE20 is {side(row['min_fde'], led[1])} the paper's LED row "
        f"({led[0]:.2f} / {led[1]:.2f}), its minADE20 {side(row['min_ade'], led[0])}."
    )


PIXEL_WALKTHROUGH = {
    "sdd": "SDD's pixels per metre differ between its scenes, and its scenes are small "
    "groups (1.45 agents per test scene). In one walkthrough (2026-12-06, synthetic scenes, "
    "not a benchmark; docs/data.md, 'SDD in pixels'): lone walkers at 3x SDD's scale (e.g. "
    "4K video) got minFDE20 90.5 px against constant velocity's 48.4; a 6-agent scene spread over "
    "about 1,300 px got 30.9 px without a neighbour radius and 11.1 px with "
    "`--neighbour-radius` 100-200; on SDD's val split 300 px cost +0.16 % minFDE20.",
}
"""A pixel dataset's measured cost of another pixel scale and of wide scenes, quoted by
``pixel_scale_note`` (hand-written: the walkthrough's numbers, docs/data.md)."""


def pixel_scale_note(dataset: str, scale: float | None) -> str:
    """A pixel dataset's limit: its models expect its pixel scale (image resolution and
    flying height), since positions are divided by a fixed data scale ``scale``, and the pace
    warning fires only above ``PACE_LIMIT`` model units per step; "" for other units."""
    spec = SPECS.get(dataset)
    if spec is None or spec.units != "px" or not scale:
        return ""
    return (f"It expects {dataset.upper()}'s pixel scale: positions are divided by a fixed "
            f"{scale:.3f} px per model unit, so video at another resolution or flying height "
            f"must be scaled to it first (and the predictions back). Nothing warns unless the "
            f"agents step more than about {PACE_LIMIT * scale:.0f} px per step ({PACE_LIMIT:g} "
            "model units, the pace warning). Radii (`--neighbour-radius`, `--collision-radius`) "
            "are in pixels. " + PIXEL_WALKTHROUGH.get(dataset, "")).strip()  # fmt: skip


def subset_note(dataset: str) -> str:
    """Where a dataset has no full-sampler row over its whole test split, the cell that
    ``benchmarks/reproduce.py`` measured on evenly spaced test agents (docs/reproduce.md's ‡
    cells), from its stored state; "" when there is none or it covers the whole split."""
    path = RESULTS / "meta" / "reproduce" / f"{dataset}_full-sampler.json"
    if not path.is_file():
        return ""
    cell = json.loads(path.read_text())
    if cell["agents"] >= cell["split_agents"]:
        return ""
    res = cell["result"]
    return (f"No full-sampler row covers its whole test split ({cell['split_agents']:,} "
            f"agent-windows); `benchmarks/reproduce.py` measured the 100-step sampler on "
            f"{cell['agents']:,} of its {cell['split_agents']:,}, evenly spaced: "
            f"{res['min_ade']:.3f} / {res['min_fde']:.3f} ({cell['date']}, docs/reproduce.md, "
            "the cells marked ‡).")  # fmt: skip


def generated_limits(name: str, kind: str, test: dict[str, Any] | None,
                     full_row: bool, scale: float | None = None) -> list[str]:  # fmt: skip
    """The card limits computed from the repository's files: a pixel dataset's scale
    (``pixel_scale_note``, from the header's ``scale``), the distance to the paper's LED
    row (``LED_GAP``), the subset full-sampler cell of a dataset without a whole-split
    full-sampler row (``full_row``: whether it has one), and a denoiser's cost as a
    predictor."""
    dataset = name.split("/")[0]
    out = []
    if scale_note := pixel_scale_note(dataset, scale):
        out.append(scale_note)
    if name in LED_GAP and test:
        paper = json.loads((ROOT / "benchmarks" / "paper_tables.json").read_text())
        out.append(led_gap(test, paper["tables"]["table1"]["rows"][LED_GAP[name]]["LED"]))
    if not full_row and (note := subset_note(dataset)):
        out.append(note)
    if kind == "denoiser":
        speed_path = RESULTS / "meta" / "speed.json"
        speed = json.loads(speed_path.read_text()) if speed_path.is_file() else {}
        own = (speed.get("models") or {}).get(f"{dataset}/generator")
        changed = own is not None and timed_weights(f"{dataset}/generator", own, speed_path,
                                                    zoo.ZOO_DIR)[0] == "other"  # fmt: skip
        if note := speed_note(speed, dataset, changed):
            out.append(note)
    return out


def _estimate_lines(estimate: dict[str, Any] | None) -> list[str]:
    """The card's line on the cost alone (the minutes above are as run, often beside other
    jobs on the same two cores)."""
    if not estimate:
        return []
    parts = [f"{k} {v} min" for k, v in estimate["minutes"].items()]
    total = round(sum(estimate["minutes"].values()), 1)
    return [
        "",
        f"Estimated alone on {machine_short(estimate['machine'])} by `python "
        f"benchmarks/train_cost.py` ({estimate['date']}): {' + '.join(parts)}"
        + (f" = {total} min" if len(parts) > 1 else "")
        + "; the minutes above are as run, when other jobs may have shared the machine.",
    ]


def _sampling_lines(sampling: dict[str, Any] | None) -> list[str]:
    if not sampling:
        return []
    how = ("each the posterior mean (no ancestral noise)" if not sampling["stochastic_steps"]
           else "with DDPM's ancestral noise")  # fmt: skip
    if sampling["tau"] == 0:
        text = ("Sampling: the generator's samples are the prediction, with no denoising step "
                "(`model.tau: 0`; the denoiser serves the diffusion score).")  # fmt: skip
    else:
        text = (f"Sampling: the generator's samples, then tau = {sampling['tau']} denoising "
                f"steps, {how}.")  # fmt: skip
    if sampling.get("agent_frame") == "heading":
        text += (" The generator sees and predicts each agent in its heading frame "
                 "(`model.agent_frame: heading`).")  # fmt: skip
    if sampling.get("history_encoder") == "temporal":
        text += (" Its encoder reads each agent's history with a GRU beside the MLP "
                 "(`model.history_encoder: temporal`).")  # fmt: skip
    if sampling.get("dropout"):
        text += (f" It was trained with dropout {sampling['dropout']:g} "
                 "(`model.generator_dropout`).")  # fmt: skip
    if sampling.get("encoder_dropout"):
        text += (f" Its encoder dropped {sampling['encoder_dropout']:g} of its activations in "
                 "training (`model.encoder_dropout`).")  # fmt: skip
    if sampling.get("context_agents"):
        text += (" Its encoder also reads the agents that leave the view before a window "
                 "ends, as neighbours only (`model.context_agents`).")  # fmt: skip
    if sampling.get("flip"):
        text += " It was trained on scenes mirrored at random (`data.flip`)."
    if sampling.get("reverse"):
        text += " It was trained on scenes played backwards at random (`data.reverse`)."
    if sampling.get("future_rank"):
        text += (f" Its mean and shifts are polynomial paths of degree at most "
                 f"{sampling['future_rank']} in time (`model.future_rank`).")  # fmt: skip
    if sampling.get("spread_scale", 1.0) != 1.0:
        text += (f" Its samples' spread about their mean is scaled by "
                 f"{sampling['spread_scale']:g} (`model.spread_scale`).")  # fmt: skip
    if sampling.get("max_log_sigma") is not None:
        text += (f" Each sample's log sigma is capped at {sampling['max_log_sigma']:g} model "
                 "units (`model.max_log_sigma`).")  # fmt: skip
    if sampling.get("ema_epochs"):
        text += (f" Its weights are a moving average of the training iterates (time constant "
                 f"{sampling['ema_epochs']:g} epochs, `generator.ema_epochs`).")  # fmt: skip
    if sampling.get("max_speed"):
        text += (f" Agents faster than {sampling['max_speed']:.3f} model units per observed step "
                 "are seen at that speed and their prediction scaled back up "
                 "(`model.max_speed`).")  # fmt: skip
    clamps = [c for c in sampling["changes"] if "max_speed" in c]
    trained_clamp = clamps[0].get("previous") if clamps else None  # before any change
    for change, notes in _merged_changes(sampling["changes"]):
        if "stochastic_steps" in change:
            state = "ancestral" if change["stochastic_steps"] else "posterior-mean"
            text += f" Set to {state} steps after training ({notes})."
        if "max_speed" in change and trained_clamp:  # trained with a clamp on
            text += (f" Trained with the speed clamp at {trained_clamp:.4f}, set to "
                     f"{change['max_speed']:.4f} ({notes}).")  # fmt: skip
        elif "max_speed" in change:
            text += (f" Speed clamp set to {change['max_speed']:.3f} after training, same "
                     f"weights ({notes}).")  # fmt: skip
        for name in ("spread_scale", "max_log_sigma", "neighbour_radius"):
            if name in change:
                value = change[name]
                shown = "null" if value is None else f"{value:g}"
                text += (f" `model.{name}` set to {shown} after training, same weights "
                         f"({notes}).")  # fmt: skip
    return [text, ""]


def _merged_changes(changes: list[dict[str, Any]]) -> list[tuple[dict[str, Any], str]]:
    """Consecutive changes of one setting as one (last change, joined notes) pair: a card says
    once where a setting ended up and why, not once per rewrite of the same value."""
    merged: list[tuple[dict[str, Any], str]] = []
    for change in changes:
        keys = set(change) - {"note", "date", "previous"}
        if merged and set(merged[-1][0]) - {"note", "date", "previous"} == keys:
            merged[-1] = (change, f"{merged[-1][1]}; {change_note(change)}")
        else:
            merged.append((change, change_note(change)))
    return merged


def _training_line(e: dict[str, Any]) -> str:
    """The card's first Training line: the machine (and where the card has it from, when
    that is not a training record), the minutes per stage and the best epoch."""
    t = e["train"]
    stages = ", ".join(f"{k} stage {v} min" for k, v in t["minutes"].items() if v is not None)
    stages += f", best validation epoch {t['epochs']}" if t.get("epochs") else ""
    source = t.get("machine_from", "training") if t["machine"] else "training"
    where = MACHINE_FROM[source].format(machine=t["machine"] or "an unrecorded machine",
                                        dataset=e["dataset"])  # fmt: skip
    if source == "training":
        text = f"{where}: {stages}."
    else:
        if any(c.startswith("OMP_NUM_THREADS=") for c in t["commands"][-1:]):
            where += ". The thread count in front of its command is that run's"
        text = f"{where}. {stages[:1].upper()}{stages[1:]}."
    den_from = t.get("denoiser_threads_from")
    if den_from:
        run = (f"`{e['denoiser']}`'s test row" if den_from == "test row"
               else f"the `pretrained` row of {e['dataset']}")  # fmt: skip
        text += (f" The denoiser's command (the first) carries the thread count of the run "
                 f"that evaluated {run}: no training record names the denoiser's "
                 "machine.")  # fmt: skip
    return text


def _scale_sentence(data: dict[str, Any]) -> str:
    """On a pixel dataset's card: the data scale that positions are divided by (the header's
    ``scale``), in which the model-unit options are given."""
    if data.get("units") != "px" or not data.get("scale"):
        return ""
    return (f" The model divides positions by its data scale, {data['scale']:.3f} px per model "
            "unit (the header's `scale`); `--max-speed` and `--trust-speed` are in model units "
            "per step.")  # fmt: skip


def card(e: dict[str, Any]) -> str:
    """A short Markdown model card."""
    d, t, test = e["data"], e["train"], e["test"]
    units = {"m": "metres", "px": "pixels"}.get(d["units"], d["units"] or "data units")
    lines = [
        f"# {e['name']}",
        "",
        f"A **{e['kind']}** ({e['method']}; predicts with the {e['sampler']} sampler), "
        f"file `{e['file']}`, weights hash `{e['hash']}`."
        + (f" Its denoiser: `{e['denoiser']}`." if e.get("denoiser") else ""),
        "",
        *_sampling_lines(e.get("sampling")),
        "```bash",
        f"trajpref evaluate --dataset {e['dataset']} --model {e['name']}",
        "```",
        "",
        SOURCE_NOTE,
        "",
        "## Data",
        "",
        f"{d['description']}. {d['t_hist']} observed -> {d['t_fut']} predicted steps, "
        f"{d['frame_interval']} s apart, {units}." + _scale_sentence(d),
        "",
        "## Training",
        "",
        _training_line(e),
        *_estimate_lines(t.get("estimate")),
        "",
        "```bash",
        *t["commands"],
        *_after_training_lines(t.get("after_training")),
        "```",
        "",
        "## Test row",
        "",
    ]
    if test:
        lines += [
            f"{test['split']} split, protocol `{test['protocol']}`, K = {test['samples']}, "
            f"seed {test['seed']} "
            f"(row `{test['method']}`, {test['date']}, evaluated on {test['machine']}):",
            "",
            "| minADE | minFDE | joint minADE | joint minFDE |",
            "|---|---|---|---|",
            f"| {test['min_ade']:.3f} | {test['min_fde']:.3f} | {test['joint_min_ade']:.3f} | "
            f"{test['joint_min_fde']:.3f} |",
            "",
            f"Measured by `{test['command']}`.",
        ]
    else:
        lines.append("No test row was measured for this model.")
    lines += ["", "## Known limits", ""]
    lines += [f"- {x}" for x in e["limits"]] or ["- None recorded beyond the README's."]
    return "\n".join(lines) + "\n"


def readme_with(text: str, listing: str) -> str:
    """The README's text with the ``<!-- models -->`` block holding ``listing``."""
    start, end = "<!-- models:start -->", "<!-- models:end -->"
    if start not in text or end not in text:
        raise SystemExit(f"README.md has no {start} ... {end} block")
    head, rest = text.split(start, 1)
    return f"{head}{start}\n```\n{listing}\n```\n{end}{rest.split(end, 1)[1]}"


def build(root: Path) -> tuple[dict[str, Any], dict[Path, str], list[str]]:
    """The index, the cards by path, and the cards whose test row names none of the file's
    digest (``card_row``'s problem lines)."""
    rows = read_rows(RESULTS)
    models = [describe(name, path, rows) for name, path in zoo.published(root).items()]
    unverified = [p for e in models if (p := e.pop("_unverified", None))]
    index = {
        "format": zoo.INDEX_FORMAT,
        "generated_by": "python benchmarks/zoo_index.py",
        "models": models,
    }
    cards = {root / e["card"]: card(e) for e in models}
    return index, cards, unverified


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true",
                        help="only check that the index and cards are up to date")  # fmt: skip
    args = parser.parse_args()
    root = zoo.ZOO_DIR
    index, cards, unverified = build(root)
    files = {root / zoo.INDEX: json.dumps(index, indent=1) + "\n", **cards}
    readme = ROOT / "README.md"
    listing = zoo.table([{**e, "indexed": True} for e in index["models"]])
    files[readme] = readme_with(readme.read_text(), listing)
    stale = [p for p, text in files.items() if not p.is_file() or p.read_text() != text]
    for problem in unverified:
        print(f"unverified test row: {problem}")
    if args.check:
        for path in stale:
            print(f"stale: {path}")
        if not stale and not unverified:
            print(f"models/{zoo.INDEX} and {len(cards)} cards are up to date (and README.md's "
                  "model listing)")  # fmt: skip
        sys.exit(1 if stale or unverified else 0)
    for path in stale:
        path.write_text(files[path])
        print(f"wrote {path}")
    print(zoo.table(zoo.entries(root)))


if __name__ == "__main__":
    main()
