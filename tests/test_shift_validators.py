"""benchmarks/shift_validators.py: the simulated shifts are built from the validation split
alone and do what their names say."""

import numpy as np
from bench import load_benchmark
from synthetic import write_tracks


def test_shifted_splits_scale_and_resample_the_validation_split(tmp_path):
    sv = load_benchmark("shift_validators")
    folder = tmp_path / "d"
    rows = [(f * 10, a, 0.2 * f + a, float(a)) for a in (1, 2) for f in range(60)]
    write_tracks(folder / "val" / "v.txt", rows)
    write_tracks(folder / "test" / "t.txt", [(f * 10, 1, float("nan"), 0) for f in range(3)])
    splits = sv.shifted_splits(str(folder), None, 2.0, 2.0)  # the test file is never read
    assert list(splits) == ["recorded", "x2", "time_step 2", "time_step 2, x2"]
    rec, big, slow, both = splits.values()
    np.testing.assert_allclose(big[0].history, 2 * rec[0].history)
    step = np.diff(slow[0].future[0, :, 0])  # read every 2nd frame: 0.4 per step
    np.testing.assert_allclose(step, 0.4, rtol=1e-5)
    np.testing.assert_allclose(both[0].future, 2 * slow[0].future)
    assert len(slow) < len(rec)  # 60 frames read every 2nd: 30 steps, 11 windows instead of 41
    assert slow.info.frame_interval == 2 * rec.info.frame_interval
