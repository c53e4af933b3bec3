"""A TrajNet++ scene row whose frame span is huge (``"e": 1e20``, or a billion frames: a typo
or a corrupt file) made the reader list every frame of it: an OverflowError past 2**63, and
24 GB of memory (the machine's OOM killer) for a span of a few billion frames, found by the
reader's fuzz test. The span is now checked by arithmetic, and only the first missing frames
are listed."""

import json
import resource
import time

import pytest

from trajpref.data.trajnet import read_trajnet
from trajpref.errors import DataError


def _file(tmp_path, end) -> str:
    """One observation-only scene spanning frames 10..``end`` and three complete ones."""
    rows = [{"scene": {"id": 9, "p": 0, "s": 10, "e": end}}]
    rows += [{"scene": {"id": i, "p": i, "s": 0, "e": 6, "fps": 2.5}} for i in range(3)]
    rows += [{"track": {"f": f, "p": p, "x": 0.5 * f, "y": p - 0.25 * f}}
             for f in range(6) for p in range(3)]  # fmt: skip
    path = tmp_path / "f.ndjson"
    path.write_text("".join(json.dumps(r) + "\n" for r in rows))
    return str(path)


@pytest.mark.parametrize("end", [1.792172702896576e20, 10**9 + 10, 3 * 10**9])
def test_a_huge_scene_span_is_a_data_error_at_once(tmp_path, end):
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    resource.setrlimit(resource.RLIMIT_AS, (8 * 2**30, hard))  # a listed span fails, not OOM
    try:
        t0 = time.perf_counter()
        with pytest.raises(DataError, match=r"scene 9: .*frames? 10, 11, 12 and \d+ more missing"):
            read_trajnet(_file(tmp_path, end), 2, 3)
        assert time.perf_counter() - t0 < 30  # no walk over the span (a generous bound)
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))
