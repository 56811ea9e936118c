"""The configuration reference: every setting of a run documented, the page up to date."""

from dataclasses import fields

import pytest

from twin.core.paths import REPO_ROOT
from twin.cosim.config import CosimConfig, from_toml
from twin.cosim.config_reference import (
    PAGE,
    attribute_docs,
    document,
    sections,
    toml_type,
    undocumented,
)


def test_every_setting_has_a_description():
    assert undocumented() == [], (
        "add 'name: [unit] meaning' to the Attributes of the class's docstring for each"
    )


def test_the_page_is_the_configuration_classes():
    assert (REPO_ROOT / PAGE).read_text() == document(), (
        "docs/config.md is out of date: run python -m twin.cosim.config_reference"
    )


def test_every_key_of_the_page_is_a_setting_toml_accepts_with_its_default():
    found = sections()
    assert found[0].path == () and found[0].cls is CosimConfig
    assert {s.title for s in found} >= {"[traffic]", "[traffic.mobil]", "[camera]"}
    for section in found:
        header = f"[{'.'.join(section.path)}]\n" if section.path else ""
        for setting in section.settings:
            if setting.type != "table" and setting.default != "unset":
                text = f"{header}{setting.key} = {setting.default}\n"
                read = from_toml(text, source="the reference")
                # the default as written on the page reads back as the default
                path = (*section.path, setting.key)
                assert _at(read, path) == _at(CosimConfig(), path), (path, setting.default)


def _at(config, path):
    for name in path:
        config = getattr(config, name)
    return config


def test_a_field_without_description_is_named():
    from dataclasses import dataclass

    @dataclass(frozen=True)
    class Half:
        """Settings.

        Attributes:
            a, b: [m] shared.
                More words.
        """

        a: float = 1.0
        b: float = 2.0
        c: float = 3.0

    assert attribute_docs(Half) == {"a": "[m] shared. More words.", "b": "[m] shared. More words."}
    assert undocumented(Half()) == ["Half.c"]
    assert [f.name for f in fields(Half)] == ["a", "b", "c"]


def test_toml_types_are_named_in_words():
    assert toml_type(float | None) == "float or unset"
    assert toml_type(tuple[float, float]) == "array of 2 floats"
    assert toml_type(tuple[str, ...]) == "array of strings"
    with pytest.raises(TypeError, match="no TOML type"):
        toml_type(dict)
