"""The study manifest: a key a researcher misspells is an error that names it."""

import json

import pytest

from trajpref.errors import DataError
from trajpref.survey.manifest import load_study


def _edit(folder, edit) -> None:
    manifest = folder / "manifest.json"
    data = json.loads(manifest.read_text())
    edit(data)
    manifest.write_text(json.dumps(data))


def _rename(obj: dict, old: str, new: str) -> None:
    obj[new] = obj.pop(old)


@pytest.mark.parametrize(
    "edit, message",
    [
        (
            lambda m: _rename(m, "instructions", "instruction"),
            "top level: unknown key 'instruction' (did you mean 'instructions'?); the keys "
            "are: build, consent, created, dataset, format, instructions, key, methods, order, "
            "scenes, synthetic, title",
        ),
        (
            lambda m: m.update(titel="Rate these"),
            "top level: unknown key 'titel' (did you mean 'title'?)",
        ),
        (
            lambda m: _rename(m["scenes"][1], "reference", "referense"),
            "scenes[1]: unknown key 'referense' (did you mean 'reference'?); the keys are: "
            "id, panels, reference",
        ),
        (
            lambda m: m["scenes"][0]["panels"][2].update(img="x.png"),
            "scenes[0].panels[2]: unknown key 'img' (did you mean 'image'?); the keys are: "
            "id, image",
        ),
        (
            lambda m: _rename(m["key"]["s02"], "stratum", "strata"),
            "key.s02: unknown key 'strata' (did you mean 'stratum'?); the keys are: agents, "
            "index, panels, source, stratum",
        ),
        (
            lambda m: _rename(m["key"]["s01"]["panels"]["B"], "ats", "ast"),
            "key.s01.panels.B: unknown key 'ast' (did you mean 'ats'?); the keys are: ade, "
            "ats, fde, fts, max_ats, max_fts, method, shown",
        ),
        (
            lambda m: m.update(colour="red"),
            "top level: unknown key 'colour'; the keys are: build,",
        ),
    ],
    ids=["instructions", "title", "scene", "panel", "key-scene", "key-panel", "no-match"],
)
def test_an_unknown_key_names_itself_the_closest_key_and_the_allowed_ones(
    synthetic_study, edit, message
):
    _edit(synthetic_study, edit)
    with pytest.raises(DataError) as err:
        load_study(synthetic_study)
    assert message in str(err.value)
    assert str(err.value).startswith(f"{synthetic_study / 'manifest.json'}: ")


def test_two_unknown_keys_are_both_named(synthetic_study):
    _edit(synthetic_study, lambda m: m.update(titel="x", instruction="y"))
    with pytest.raises(DataError, match="unknown keys 'instruction' \\(did you mean "
                       "'instructions'\\?\\), 'titel' \\(did you mean 'title'\\?\\)"):  # fmt: skip
        load_study(synthetic_study)


def test_the_records_dataset_and_build_take_any_key(synthetic_study):
    _edit(synthetic_study, lambda m: (m["dataset"].update(note="x"), m["build"].update(y=1)))
    assert load_study(synthetic_study).dataset["note"] == "x"
