"""A tracker id switch in one's own data: evaluate/predict warn once when an agent's position
jumps more than ``timing.JUMP_LIMIT`` model units in one observed step (the 90 % quantile of
the pace warning does not see one agent), and say nothing on ordinary walkers."""

from __future__ import annotations

import pytest

from trajpref.cli import main


def _walkers(root, jump: float):
    """``test/walk.txt`` (frame, id, x, y; 10 frames = 0.4 s, metres): three walkers for 20
    frames at 0.5 m per step; walker 1 jumps ``jump`` metres along y at its 4th step."""
    rows = []
    for k in range(20):
        for a in (1, 2, 3):
            y = 2.0 * a + (jump if a == 1 and k >= 4 else 0.0)
            rows.append(f"{10 * k}\t{a}\t{0.5 * k:.2f}\t{y:.2f}")
    (root / "test").mkdir(parents=True)
    (root / "test" / "walk.txt").write_text("\n".join(rows) + "\n")
    return root


@pytest.mark.parametrize(("jump", "warned"), [(20.0, True), (0.0, False)])
def test_an_agent_jumping_in_its_history_is_warned_of_once(tmp_path, capsys, jump, warned):
    data = _walkers(tmp_path / "d", jump)
    out = str(tmp_path / "p.npz")
    argv = ["predict", "--dataset", str(data), "--model", "zara1/generator", "--units", "m",
            "--frame-interval", "0.4", "--no-progress", "--out", out]  # fmt: skip
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert err.count("jumps more than 5 model units") == (1 if warned else 0)
    assert ("tracker id switch" in err) == warned
