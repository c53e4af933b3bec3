"""``trajpref survey build | serve | analyze | export | simulate``: registered on the main parser by
:func:`add_parser`."""

from __future__ import annotations

import argparse
import functools
import json
import shlex
from collections.abc import Callable
from pathlib import Path

from trajpref.errors import ConfigError

# The survey's modules are imported by the commands that use them, not here: ``trajpref.cli``
# imports this module to build its parser, and analyze (scipy) and build (matplotlib, torch)
# would otherwise slow every command's start.


def add_parser(
    subparsers,
    *,
    add_data_args: Callable[[argparse.ArgumentParser], None],
    check_data_args: Callable[[argparse.Namespace], None],
    warn_if_trained_otherwise: Callable[..., None],
) -> argparse.ArgumentParser:
    """Add ``survey`` and its five commands to the main parser's sub-commands.

    ``survey build`` reads data as ``trajpref evaluate`` does, with the main CLI's own data
    options, their checks and its warning for a model trained on data in other units or at
    another step: ``trajpref.cli`` passes them in (``survey`` sits below ``cli`` in the layers
    of docs/architecture.md, so it may not import them)."""
    sv = subparsers.add_parser("survey", help="a human-evaluation study (the paper's Table 3): "
                               "build, serve, simulate, analyze, export")  # fmt: skip
    sub = sv.add_subparsers(dest="survey_command", required=True, metavar="COMMAND")

    b = sub.add_parser("build", help="pick scenes, render each method's top futures, blind them")
    add_data_args(b)  # --dataset, --split, --data-root, ... as `trajpref evaluate` has them
    b.add_argument("--models", nargs="+", required=True, metavar="NAME=MODEL",
                   help="the methods: a name and 'cv', a published model (DATASET/NAME, see "
                   "`trajpref models`) or a checkpoint path, e.g. gen=zara1/generator")  # fmt: skip
    b.add_argument("--scorer", default=None, help="the denoiser that scores every method: a "
                   "published model or a checkpoint path, e.g. zara1/denoiser (default: the "
                   "first checkpoint among --models)")  # fmt: skip
    b.add_argument("--scenes", type=int, default=12, help="scenes in the study (default 12)")
    b.add_argument("--samples", type=int, default=20, help="K, samples per agent (default 20)")
    b.add_argument("--top", type=int, default=2, help="futures shown per agent (default 2)")
    b.add_argument("--seed", type=int, default=0,
                   help="seed of the draw, sampling, shuffling (default 0)")  # fmt: skip
    b.add_argument("--min-agents", type=int, default=1, help="smallest scene (default 1)")
    b.add_argument("--max-agents", type=int, default=8,
                   help="largest scene drawn for the study, in agents (default 8): a "
                   "scene-size filter, not evaluate's batch size")  # fmt: skip
    b.add_argument("--min-gap", type=int, default=None, help="picked scenes are this many "
                   "positions apart in the split (default: a window's frames, 20 for the "
                   "published models: no shared frames)")  # fmt: skip
    b.add_argument("--strata", type=int, default=3, help="scene-size strata (default 3)")
    b.add_argument("--ground-truth", default="rated", choices=["rated", "reference"],
                   help="rated: the real futures are one more blinded panel (default); "
                   "reference: shown beside every panel, not rated")  # fmt: skip
    b.add_argument("--title", default="Which predicted paths look human?",
                   help="page title (default %(default)r)")  # fmt: skip
    b.add_argument("--consent", default=None, metavar="FILE", help="a UTF-8 text file: the "
                   "consent text every rater reads and agrees to ('I agree') before the first "
                   "picture; the agreement is recorded per rater (default: none)")  # fmt: skip
    b.add_argument("--fixed-order", action="store_true", help="show every rater the scenes "
                   "and panels in one order (shuffled once at build time); default: each rater "
                   "sees an order of their own, so that position effects spread over the "
                   "methods")  # fmt: skip
    b.add_argument("--device", default="auto", help="auto, cpu or cuda (default auto)")
    b.add_argument("--out", required=True, help="the new study folder")
    b.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    b.set_defaults(
        func=functools.partial(
            cmd_build,
            check_data_args=check_data_args,
            warn_if_trained_otherwise=warn_if_trained_otherwise,
        )
    )

    s = sub.add_parser("serve", help="the rating page; answers go to STUDY/answers.sqlite")
    s.add_argument("study", help="a study folder made by `survey build`")
    s.add_argument("--host", default="127.0.0.1",
                   help="address to listen on (default 127.0.0.1: this machine only)")  # fmt: skip
    s.add_argument("--port", type=int, default=8000, help="port (default 8000; 0: any free)")
    s.add_argument("--db", default=None, help="answers database (default STUDY/answers.sqlite)")
    s.add_argument("--max-body", type=int, default=4096, help="request body limit in bytes")
    s.add_argument("--quiet", action="store_true", help="no access log")
    s.set_defaults(func=cmd_serve)

    a = sub.add_parser("analyze", help="Table 3: human scores, ATS/FTS, tests, agreement")
    a.add_argument("study", help="a study folder")
    a.add_argument("--db", default=None, help="answers database (default STUDY/answers.sqlite)")
    a.add_argument("--out", default=None, help="folder for analysis.md/.json/.png "
                   "(default: the study folder)")  # fmt: skip
    _add_rater_args(a)
    a.add_argument("--json", action="store_true", help="print JSON instead of Markdown")
    a.set_defaults(func=cmd_analyze)

    e = sub.add_parser("export", help="the answers as a CSV table (R, pandas, SPSS)")
    e.add_argument("study", help="a study folder")
    e.add_argument("--csv", required=True, metavar="FILE", help="the CSV file to write: one "
                   "row per answer, with the method and scores behind each panel (owner-only: "
                   "rater ids are personal data)")  # fmt: skip
    e.add_argument("--db", default=None, help="answers database (default STUDY/answers.sqlite)")
    _add_rater_args(e)
    e.set_defaults(func=cmd_export)

    m = sub.add_parser("simulate", help="synthetic raters (demos and tests only)")
    m.add_argument("study", help="a study folder")
    m.add_argument("--raters", type=int, default=20, help="how many (default 20)")
    m.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    m.add_argument("--prefix", default="synthetic", help="rater ids PREFIX-01, ... "
                   "(default synthetic)")  # fmt: skip
    m.add_argument("--db", default=None, help="answers database (default STUDY/answers.sqlite)")
    m.set_defaults(func=cmd_simulate)
    return sv


def _add_rater_args(p: argparse.ArgumentParser) -> None:
    """Whose answers ``analyze`` and ``export`` use: ``--raters`` and ``--exclude-rater``."""
    p.add_argument(
        "--raters",
        default="auto",
        choices=["auto", "human", "synthetic", "all"],
        help="whose answers (default auto: human raters if any, else synthetic)",
    )
    p.add_argument("--exclude-rater", action="append", default=[], metavar="ID",
                   help="leave this rater's answers out, e.g. one who failed an attention check "
                   "or a test run (repeatable; any case)")  # fmt: skip


def parse_models(items: list[str]) -> dict[str, str]:
    """``NAME=MODEL`` items -> {name: model}; a bare ``cv`` is ``cv=cv``."""
    out: dict[str, str] = {}
    for item in items:
        name, sep, spec = item.partition("=")
        if not sep:
            if item != "cv":
                raise ConfigError(f"--models {item!r}: write NAME=MODEL, e.g. mine=run/"
                                  "generator.safetensors")  # fmt: skip
            name, spec = "cv", "cv"
        name, spec = name.strip(), spec.strip()
        if not name or not spec:
            raise ConfigError(f"--models {item!r}: write NAME=MODEL")
        if name in out:
            raise ConfigError(f"--models: the name {name!r} is given twice")
        out[name] = spec
    return out


def read_consent(path: str | None) -> str:
    """The text of ``--consent FILE`` (UTF-8, outer white space stripped); "" without it."""
    if path is None:
        return ""
    try:
        text = Path(path).read_text(encoding="utf-8").strip()
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"--consent {path}: cannot read it as UTF-8 text "
                          f"({getattr(exc, 'strerror', None) or exc})") from None  # fmt: skip
    if not text:
        raise ConfigError(f"--consent {path}: the file is empty")
    return text


def cmd_build(args, check_data_args: Callable[[argparse.Namespace], None],
              warn_if_trained_otherwise: Callable[..., None]) -> int:  # fmt: skip
    from trajpref.survey.build import BuildConfig, build_study

    check_data_args(args)  # fills in --frame-interval and --units, checks the read options
    cfg = BuildConfig(
        dataset=args.dataset, models=parse_models(args.models), split=args.split,
        data_root=args.data_root, units=args.units,
        frame_interval=args.frame_interval if args._interval_given else None,
        delimiter=args.delimiter, max_gap=args.max_gap, max_coord=args.max_coord,
        time_step=args.time_step, t_hist=args.history, t_fut=args.future,
        protocol=args.protocol, holdout_scene=args.holdout_scene,
        scorer=args.scorer, scenes=args.scenes, samples=args.samples, top=args.top,
        seed=args.seed, min_agents=args.min_agents, max_agents=args.max_agents,
        min_gap=args.min_gap, strata=args.strata, ground_truth=args.ground_truth,
        title=args.title, device=args.device, consent=read_consent(args.consent),
        fixed_order=args.fixed_order,
    )  # fmt: skip

    def warn(ds) -> None:  # as `evaluate` warns, for every checkpoint: methods and scorer
        for spec in dict.fromkeys([*cfg.models.values(), *([cfg.scorer] if cfg.scorer else [])]):
            warn_if_trained_otherwise(spec, ds)  # ds.info: its step, source and time step

    study = build_study(cfg, args.out, progress=not args.no_progress, on_data=warn)
    print(f"wrote {study.folder}: {len(study.scenes)} scenes x {len(study.methods)} panels "
          f"({', '.join(study.methods)}), blinded; serve it with "
          f"`trajpref survey serve {shlex.quote(str(study.folder))}`")  # fmt: skip
    return 0


def cmd_serve(args) -> int:

    # imported here: the web server's packages are needed only to serve a study
    from trajpref.survey.server import serve

    serve(args.study, args.host, args.port, args.db, args.max_body, args.quiet)
    return 0


def cmd_analyze(args) -> int:
    from trajpref.survey.analyze import run_analysis

    result, paths = run_analysis(args.study, args.db, args.out, args.raters, args.exclude_rater)
    if args.json:
        print(json.dumps(result.to_dict()))
    else:
        print(result.markdown())
        print(f"wrote {paths['markdown']}, {paths['json']}, {paths['figure']}")
    return 0


def cmd_export(args) -> int:
    from trajpref.survey.export import export_csv

    done = export_csv(args.study, args.csv, args.db, args.raters, args.exclude_rater)
    label = " SYNTHETIC raters or study: not human data;" if done["synthetic"] else ""
    print(
        f"wrote {done['answers']} answers of {done['raters']} raters ({done['kind']}) to "
        f"{done['path']} (owner-only: rater ids are personal data);{label} columns: "
        "rater, kind, ..., method, social, kinetics, human_score, ats, fts (empty for the "
        "ground truth), ade, fde, ..., study_id, weights_hash, model_hash (docs/survey.md)"
    )
    return 0


def cmd_simulate(args) -> int:
    from trajpref.survey.manifest import DATABASE, load_study
    from trajpref.survey.simulate import SimulateConfig, simulate
    from trajpref.survey.store import AnswerStore

    cfg = SimulateConfig(raters=args.raters, seed=args.seed, prefix=args.prefix)
    study = load_study(args.study)
    store = AnswerStore(args.db or study.folder / DATABASE, study)
    try:
        ids = simulate(study, store, cfg)
    finally:
        store.close()
    print(f"wrote {len(ids)} SYNTHETIC raters ({ids[0]} .. {ids[-1]}) x {study.num_panels} "
          f"panels to {store.path}: for demos and tests only, not human data")  # fmt: skip
    return 0
