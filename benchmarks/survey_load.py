"""Load test of ``trajpref survey serve`` (a benchmark, not a timed test).

Builds a synthetic study (12 scenes x 5 panels by default), starts the real command in its own
process on 127.0.0.1 with a fresh database, and lets 50 simulated raters (one thread and one
keep-alive connection each) start together and each answer every panel over HTTP, going back
to change about 10 % of their answers, then submit. Then it checks the database: every
(rater, panel) exactly once, holding the last value sent, with one revision per PUT, every
rater submitted; and that no response was a 5xx. Prints answers per second and the latency
percentiles of the answers; exits 1 if a check fails.

    python benchmarks/survey_load.py [--raters 50] [--scenes 12] [--methods 4]

Traffic goes to 127.0.0.1 only; every loop is bounded (one pass over the study per rater).
"""

from __future__ import annotations

import argparse
import http.client
import json
import os
import platform
import random
import sqlite3
import sys
import tempfile
import threading
import time
from datetime import datetime, timezone
from pathlib import Path
from urllib.parse import urlsplit

from trajpref.errors import ConfigError
from trajpref.survey.server import serve_subprocess
from trajpref.survey.study import make_synthetic_study


def rater_session(
    host: str, port: int, rater: str, seed: int, revisit: float, start: threading.Barrier, out: dict
) -> None:
    """One rater: load the study, answer every panel (revisiting some), submit."""
    rng = random.Random(seed)
    conn = http.client.HTTPConnection(host, port, timeout=30)
    latencies, statuses, sent = [], [], {}

    def call(method: str, path: str, body: dict | None = None) -> dict:
        headers = {"Content-Type": "application/json"} if body is not None else {}
        data = json.dumps(body).encode() if body is not None else None
        t0 = time.perf_counter()
        conn.request(method, path, body=data, headers=headers)
        resp = conn.getresponse()
        payload = resp.read()
        dt = time.perf_counter() - t0
        statuses.append(resp.status)
        if method == "PUT":
            latencies.append(dt)
        return json.loads(payload) if payload else {}

    try:
        start.wait()
        study = call("GET", "/api/study")
        call("GET", f"/api/raters/{rater}")
        panels = [(s["id"], p["id"]) for s in study["scenes"] for p in s["panels"]]
        for i, (scene, panel) in enumerate(panels):
            ratings = {"social": rng.randint(1, 5), "kinetics": rng.randint(1, 5)}
            call("PUT", f"/api/raters/{rater}/answers/{scene}/{panel}", ratings)
            sent.setdefault((scene, panel), []).append(ratings)
            if i and rng.random() < revisit:  # go back and change an earlier answer
                s, p = panels[rng.randrange(i)]
                ratings = {"social": rng.randint(1, 5), "kinetics": rng.randint(1, 5)}
                call("PUT", f"/api/raters/{rater}/answers/{s}/{p}", ratings)
                sent[(s, p)].append(ratings)
        out["submitted"] = call("POST", f"/api/raters/{rater}/submit", {"submit": True}).get(
            "submitted", False
        )
    except Exception as exc:  # a failed connection is a failed check, reported below
        out["error"] = f"{type(exc).__name__}: {exc}"
    finally:
        conn.close()
    out.update(latencies=latencies, statuses=statuses, sent=sent)


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q / 100 * len(ordered)))]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--raters", type=int, default=50)
    ap.add_argument("--scenes", type=int, default=12)
    ap.add_argument("--methods", type=int, default=4, help="methods besides the ground truth")
    ap.add_argument("--revisit", type=float, default=0.1, help="share of answers changed later")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        methods = tuple(f"method{i + 1}" for i in range(args.methods))
        study = make_synthetic_study(
            Path(tmp) / "study", scenes=args.scenes, methods=methods, seed=args.seed
        )
        print(
            f"synthetic study: {len(study.scenes)} scenes, {study.num_panels} panels "
            f"({time.perf_counter() - t0:.1f} s to render)"
        )
        try:
            server, address = serve_subprocess(study.folder)
        except ConfigError as exc:
            print(exc, file=sys.stderr)
            return 1
        try:
            url = urlsplit(address)
            start = threading.Barrier(args.raters + 1)
            results = [{} for _ in range(args.raters)]
            threads = [
                threading.Thread(
                    target=rater_session,
                    args=(
                        url.hostname,
                        url.port,
                        f"load-{i:03d}",
                        args.seed * 1000 + i,
                        args.revisit,
                        start,
                        results[i],
                    ),
                )
                for i in range(args.raters)
            ]
            for t in threads:
                t.start()
            start.wait()
            t1 = time.perf_counter()
            for t in threads:
                t.join(600)
            wall = time.perf_counter() - t1
        finally:
            server.terminate()
            server.wait(30)
            server.stdout.close()
            server.stderr.close()

        latencies = [x for r in results for x in r["latencies"]]
        statuses = [s for r in results for s in r["statuses"]]
        errors = [r["error"] for r in results if "error" in r]
        with sqlite3.connect(study.folder / "answers.sqlite") as db:
            rows = db.execute(
                "SELECT rater, scene, panel, social, kinetics, revision FROM answers"
            ).fetchall()
            submitted = db.execute(
                "SELECT COUNT(*) FROM raters WHERE submitted_at IS NOT NULL"
            ).fetchone()[0]
        expected = {}
        for i, r in enumerate(results):
            for (scene, panel), sent in r["sent"].items():
                expected[(f"load-{i:03d}", scene, panel)] = (
                    sent[-1]["social"],
                    sent[-1]["kinetics"],
                    len(sent),
                )
        stored = {(r, s, p): (a, b, v) for r, s, p, a, b, v in rows}
        checks = {
            "every answer stored exactly once": len(rows)
            == len(stored)
            == len(expected)
            == args.raters * study.num_panels,
            "stored values are the last ones sent, one revision per PUT": stored == expected,
            "every rater submitted": submitted == args.raters,
            "no 5xx responses": not any(s >= 500 for s in statuses),
            "no failed requests": not errors and all(s < 400 for s in statuses),
        }
        puts = len(latencies)
        print(
            f"date {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC; machine "
            f"{platform.machine()}, {os.cpu_count()} CPU cores, Python "
            f"{platform.python_version()}, SQLite {sqlite3.sqlite_version}"
        )
        print(
            f"{args.raters} concurrent raters x {study.num_panels} panels: {puts} PUTs "
            f"({len(rows)} distinct answers, {puts - len(rows)} updates) in {wall:.2f} s"
        )
        print(f"answers per second: {puts / wall:.0f}")
        print(
            f"answer latency: p50 {1000 * percentile(latencies, 50):.1f} ms, "
            f"p99 {1000 * percentile(latencies, 99):.1f} ms, "
            f"max {1000 * max(latencies):.1f} ms"
        )
        print(
            f"responses: {len(statuses)}, 5xx: {sum(s >= 500 for s in statuses)}, "
            f"4xx: {sum(400 <= s < 500 for s in statuses)}"
        )
        for name, ok in checks.items():
            print(f"  [{'ok' if ok else 'FAILED'}] {name}")
        for e in errors[:5]:
            print(f"  error: {e}")
        return 0 if all(checks.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
