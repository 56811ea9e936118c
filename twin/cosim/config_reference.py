"""The configuration reference, ``docs/config.md``, generated from the configuration
classes themselves.

Every setting of a run's TOML is a field of :class:`~twin.cosim.config.CosimConfig` or
of a dataclass nested in it (``[traffic]``, ``[camera]``, ``[controller.acc]``, ...).
Each class documents its fields in the ``Attributes:`` section of its docstring, one
entry a field (``name: [unit] meaning``; ``a, b: ...`` for fields that share one);
this module reads those entries, the fields' types and the defaults of
``CosimConfig()``, and writes one table per TOML section. ``python -m
twin.cosim.config_reference`` rewrites the page; a test fails while it is out of date
or while a field has no entry.
"""

import inspect
import json
import math
import re
from dataclasses import dataclass, fields, is_dataclass
from enum import Enum
from pathlib import Path
from types import NoneType, UnionType
from typing import Union, get_args, get_origin, get_type_hints

import numpy as np

from twin.core.atomic import atomic_file
from twin.cosim.config import CosimConfig

PAGE = Path("docs") / "config.md"
#: An entry of an ``Attributes:`` section: ``name: text`` or ``a, b: text``.
ENTRY = re.compile(r"^(\w+(?:, \w+)*):\s*(.*)$")
#: A unit at the start of a description: ``[m/s] ...``.
UNIT = re.compile(r"^\[([^\]]+)\]\s*(.*)$", re.S)


@dataclass(frozen=True)
class Setting:
    """One key of a TOML section.

    Attributes:
        key: the key in its section.
        type: its TOML type, in words (``float``, ``array of 2 floats``, ``table``).
        default: its default as TOML (``unset`` for no value).
        unit: its unit, ``-`` where it has none.
        meaning: what it sets, from the class's docstring.
    """

    key: str
    type: str
    default: str
    unit: str
    meaning: str


@dataclass(frozen=True)
class Section:
    """One TOML section: a configuration class at a place in the run's configuration.

    Attributes:
        path: the table's keys from the top (``("controller", "acc")``); empty at the top.
        cls: the class the section is parsed into.
        about: what the section is, from the parent's description of it.
        settings: its keys, in the class's order.
    """

    path: tuple[str, ...]
    cls: type
    about: str
    settings: tuple[Setting, ...]

    @property
    def title(self) -> str:
        """The TOML table header (``[controller.acc]``), or ``top level``."""
        return f"[{'.'.join(self.path)}]" if self.path else "top level"

    @property
    def anchor(self) -> str:
        """The section's heading anchor in the page (as MkDocs makes it)."""
        return _slug(self.title)


def attribute_docs(cls: type) -> dict[str, str]:
    """The description of each field of ``cls`` from its docstring's ``Attributes:``
    section, by field name (fields sharing an entry share its text)."""
    doc = inspect.getdoc(cls) or ""
    lines = doc.splitlines()
    if "Attributes:" not in lines:
        return {}
    found: dict[str, list[str]] = {}
    current: list[str] = []
    for line in lines[lines.index("Attributes:") + 1 :]:
        if line and not line.startswith(" "):
            break  # the next section
        entry = ENTRY.match(line[4:]) if line.startswith("    ") and line[4:5] != " " else None
        if entry:
            current = [entry.group(2)]
            for name in entry.group(1).split(", "):
                found[name] = current
        elif line.strip():
            current.append(line.strip())
    return {name: " ".join(text).strip() for name, text in found.items()}


def undocumented(config: object = None) -> list[str]:
    """``Class.field`` of every setting with no entry in its class's ``Attributes:``."""
    missing = []
    for cls in _classes(CosimConfig() if config is None else config):
        docs = attribute_docs(type(cls))
        missing += [f"{type(cls).__name__}.{f.name}" for f in fields(cls) if not docs.get(f.name)]
    return missing


def sections(config: CosimConfig | None = None) -> list[Section]:
    """The TOML sections of a run's configuration, top level first, each followed by
    its nested sections; defaults are those of ``config`` (default: ``CosimConfig()``).

    Raises:
        ValueError: a field has no description (naming it), or a type this reference
            cannot write.
    """
    config = CosimConfig() if config is None else config
    missing = undocumented(config)
    if missing:
        raise ValueError(
            f"settings without a description: {', '.join(missing)}; add 'name: [unit] "
            "meaning' to the Attributes section of the class's docstring"
        )
    about = inspect.getdoc(CosimConfig).split("\n\n")[0]
    return _sections(config, (), about)


def document(config: CosimConfig | None = None) -> str:
    """``docs/config.md``: the configuration reference, for people."""
    found = sections(config)
    out = [
        "# Configuration reference",
        "",
        "Every setting of a run (`twin run`, and each episode of `twin eval` and",
        "`twin dataset`), as a TOML key. A run is configured as preset (`--scenario A`",
        "or `B`) < TOML file (`--config run.toml`) < `--set KEY=VALUE` (a dotted key, e.g.",
        "`--set traffic.hov_share=0.3`) < flags (`--road`, `--lane`, ...). Unknown keys",
        "and impossible values are errors that name them. Each run writes its resolved",
        "configuration as `config.toml`, which loads back with `--config`.",
        "",
        "Generated from the configuration classes (`twin/cosim/config.py` and the classes",
        "it nests) by `python -m twin.cosim.config_reference`; do not edit. Defaults are",
        "those of a configuration without a preset; the presets A and B set `scenario`,",
        "`road`, `lane` and `x`. Units are SI; `-` marks a setting without one.",
        "",
        "```toml",
        'scenario = "B"',
        "t_max = 60.0",
        'world = "kinematic"',
        "",
        "[traffic]",
        "hov_share = 0.3",
        "",
        "[controller.follower_stopper]",
        "desired_speed = 25.0",
        "```",
        "",
        "Sections: " + ", ".join(f"[`{s.title}`](#{s.anchor})" for s in found) + ".",
    ]
    for section in found:
        out += [
            "",
            f"## {section.title}",
            "",
            f"`{section.cls.__name__}`: {_markdown(section.about)}",
            "",
            "| key | type | default | unit | meaning |",
            "|---|---|---|---|---|",
        ]
        for s in section.settings:
            out.append(
                f"| `{s.key}` | {s.type} | `{s.default}` | {s.unit} | {_markdown(s.meaning)} |"
            )
    return "\n".join(out) + "\n"


def write(out: str | Path = PAGE) -> Path:
    """Write :func:`document` to ``out`` whole or not at all; return ``out``."""
    text = document()
    with atomic_file(out) as tmp:
        tmp.write_text(text)
    return Path(out)


def _classes(config: object) -> list:
    """``config`` and every configuration nested in it, depth first."""
    found = [config]
    for f in fields(config):
        value = getattr(config, f.name)
        if is_dataclass(value):
            found += _classes(value)
    return found


def _sections(config: object, path: tuple[str, ...], about: str) -> list[Section]:
    """The section of ``config`` at ``path`` (described by ``about``), then those of the
    configurations nested in it, depth first."""
    cls = type(config)
    docs = attribute_docs(cls)
    hints = get_type_hints(cls)
    settings, nested = [], []
    for f in fields(config):
        value = getattr(config, f.name)
        unit, meaning = _unit(docs[f.name])
        if is_dataclass(value):
            title = f"[{'.'.join((*path, f.name))}]"
            link = f"the [`{title}`](#{_slug(title)}) section"
            settings.append(Setting(f.name, "table", "-", "-", f"{meaning} See {link}."))
            nested += _sections(value, (*path, f.name), meaning)
        else:
            settings.append(
                Setting(f.name, toml_type(hints[f.name]), toml_value(value), unit, meaning)
            )
    return [Section(path, cls, about, tuple(settings)), *nested]


def toml_type(hint) -> str:
    """A field's type annotation as its TOML type, in words.

    Raises:
        TypeError: a type the TOML reader does not take.
    """
    origin, args = get_origin(hint), get_args(hint)
    if origin in (Union, UnionType):
        # per-vehicle arrays are given in code; a TOML file gives one number for all
        kinds = [a for a in args if a not in (NoneType, np.ndarray)]
        text = " or ".join(toml_type(a) for a in kinds)
        return f"{text} or unset" if NoneType in args else text
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return f"array of {_plural(args[0])}"
        if len(set(args)) == 1:
            return f"array of {len(args)} {_plural(args[0])}"
    if hint is bool:
        return "boolean"
    if hint in (int, float):
        return {int: "integer", float: "float"}[hint]
    if hint is str:
        return "string"
    if isinstance(hint, type) and issubclass(hint, Enum):
        return "string: " + " or ".join(f'"{member.value}"' for member in hint)
    raise TypeError(f"no TOML type for {hint!r}")


def toml_value(value) -> str:
    """A default as it is written in TOML (``unset`` for ``None``)."""
    if value is None:
        return "unset"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, Enum):
        return json.dumps(value.value)
    if isinstance(value, float) and not math.isfinite(value):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, tuple | list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    raise TypeError(f"no TOML value for {value!r}")


def _plural(hint) -> str:
    """The elements of an array, in words: ``floats``, ``arrays of 2 floats``."""
    word = toml_type(hint)
    return f"{word}s" if " " not in word else word.replace("array", "arrays", 1)


def _unit(text: str) -> tuple[str, str]:
    """A description's leading ``[unit]`` and the rest (``-`` where it has none)."""
    match = UNIT.match(text)
    if match:
        return match.group(1), match.group(2)
    return "-", text


def _markdown(text: str) -> str:
    """A docstring's reStructuredText (``x``, :mod:`x`) as Markdown, safe in a table."""
    text = re.sub(r":\w+:`~?([^`]+)`", r"`\1`", text).replace("``", "`")
    return text.replace("|", "\\|")


def _slug(title: str) -> str:
    """A heading's anchor as MkDocs' table of contents makes it."""
    return re.sub(r"[\s]+", "-", re.sub(r"[^\w\s-]", "", title).strip().lower())


if __name__ == "__main__":
    from twin.core.paths import REPO_ROOT

    print(write(REPO_ROOT / PAGE))
