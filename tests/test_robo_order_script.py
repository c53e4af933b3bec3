"""benchmarks/robo_order.py: a scene's agents listed in another order, nothing else changed."""

import numpy as np
from bench import load_benchmark
from synthetic import make_scene


def test_reordered_lists_the_same_agents_in_the_given_order():
    ro = load_benchmark("robo_order")
    scene = make_scene(3)
    out = ro.reordered(scene, (2, 0, 1))
    np.testing.assert_array_equal(out.history, scene.history[[2, 0, 1]])
    np.testing.assert_array_equal(out.future, scene.future[[2, 0, 1]])
    np.testing.assert_array_equal(out.agent_type, scene.agent_type[[2, 0, 1]])
    assert out.scene_id == scene.scene_id
    np.testing.assert_array_equal(ro.reordered(scene, (0, 1, 2)).history, scene.history)
