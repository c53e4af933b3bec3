"""benchmarks/attention_speed.py on real data: both forms are timed, and the layer keeps its
own (factored) forward afterwards."""

from bench import load_benchmark

from trajpref.models import layers


def test_both_forms_are_timed_and_the_factored_form_is_restored(data_root):
    speed = load_benchmark("attention_speed")
    factored = layers.SocialAttention.forward
    result = speed.time_stage("robo", "generator", data_root, batches=1, repeats=1)
    assert layers.SocialAttention.forward is factored
    assert result["seconds"]["direct"] > 0 and result["seconds"]["factored"] > 0
    assert result["precision"] in ("fp32", "bf16")
