"""Sampling options on pixel data: --max-log-sigma none lifts a generator file's cap on
its samples' sigma, as --neighbour-radius none lifts its radius (the published sdd/generator
has a cap of 1 written in after training); the radius help names pixels for sdd."""

import json
import shutil

from trajpref.cli import main
from trajpref.models import checkpoint as ckpt


def _evaluate(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_max_log_sigma_none_samples_a_capped_file_without_its_cap(capsys, tmp_path, tiny_run,
                                                                  walks):  # fmt: skip
    capped = tmp_path / "generator.safetensors"
    shutil.copy(tiny_run / "generator.safetensors", capped)
    shutil.copy(tiny_run / "denoiser.safetensors", tmp_path / "denoiser.safetensors")
    assert ckpt.set_generator_setting(capped, "max_log_sigma", -8.0, "a cap that binds")
    base = ["evaluate", "--dataset", walks, "--split", "test", "--samples", "4", "--json",
            "--no-progress", "--model", capped]  # fmt: skip
    results = {}
    for value in (None, "none", "NONE", "1e6"):
        code, out, err = _evaluate(capsys, *base, *(["--max-log-sigma", value] if value else []))
        assert code == 0, err
        results[value] = json.loads(out)
    assert results[None]["max_log_sigma"] == -8.0  # the file's own cap
    assert results["none"]["max_log_sigma"] is None and results["NONE"]["max_log_sigma"] is None
    assert results["none"]["min_ade"] == results["1e6"]["min_ade"]  # no cap = one above all
    assert results["none"]["min_ade"] != results[None]["min_ade"]
    # the digest of what predicted changes with the cap lifted, as with any other value
    assert results["none"]["model_hash"] != results[None]["model_hash"]


def test_max_log_sigma_refuses_a_word_other_than_none(capsys, tiny_run, walks):
    code, _, err = _evaluate(capsys, "evaluate", "--dataset", walks, "--split", "test",
                             "--model", tiny_run / "generator.safetensors", "--max-log-sigma",
                             "off", "--no-progress")  # fmt: skip
    assert code == 2 and "--max-log-sigma" in err and "none" in err


def test_the_radius_help_names_the_units_of_each_kind_of_data(capsys):
    """--neighbour-radius is in the data's units; its help once spoke of metres only (about
    16 m), with no word for sdd's pixels."""
    code = main(["evaluate", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert code == 0
    radius = out.split("--neighbour-radius R|none", 2)[2].split("--device", 1)[0]
    assert "metres for ETH/UCY" in radius and "pixels for sdd" in radius


def test_an_option_equal_to_the_files_own_setting_keeps_its_digest():
    """--max-log-sigma none on a file without a cap samples exactly as the file does, so the
    result names the file's own model_hash; hotel/generator's config predates the key, and
    the option had added it, naming another digest for the same predictions."""
    from trajpref.cli import _model_fields, build_parser

    header = ckpt.read_checkpoint_header(ckpt.resolve_path("hotel/generator"))
    assert "max_log_sigma" not in header["config"]["model"]  # written before the key existed

    def digest(*extra):
        args = build_parser().parse_args(
            ["evaluate", "--dataset", "hotel", "--model", "hotel/generator", *extra]
        )
        return _model_fields(args)["model_hash"]

    assert digest("--max-log-sigma", "none") == digest()
    assert digest("--max-log-sigma", "1") != digest()  # a cap that is not the file's
