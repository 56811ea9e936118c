"""The folder of a resumable run (a dataset, an evaluation): claimed once with an
identity (what it is made of), recognised on a rerun, refused when it holds something
else. Work already finished in it is kept; the same command resumes it.

The identity is a JSON marker file whose ``format`` names the kind of folder; a rerun
must bring the same identity, setting by setting (nested tables are compared key by
key, and a TOML document held as text is compared as its settings), so that the
results it adds match those already there. A setting the folder does not hold (one
added to the twin since the folder was made) matches when it is asked at its default,
which is what the folder was made with.
"""

import json
import tomllib
from pathlib import Path

from twin.core.atomic import atomic_file, remove_stale
from twin.core.errors import TwinError


def claim(
    out: Path,
    marker: str,
    identity: dict,
    *,
    kind: str,
    noun: str,
    error: type[TwinError] = TwinError,
    files: dict[str, str] | None = None,
    toml: tuple[str, ...] = (),
    defaults: dict | None = None,
    hint: str = "",
) -> None:
    """Make ``out`` the folder of ``identity``, or check that it already is.

    Args:
        out: the folder (created with its parents when missing).
        marker: the identity file's name in it; ``identity["format"]`` its format.
        kind: what the folder is, for people (``i24-twin dataset``); noun: what it
            holds, in the list of differences (``dataset``).
        error: the error raised, a :class:`TwinError` of the caller's.
        files: other files written with the marker of a new folder (name -> text),
            written first: a folder with its marker is complete.
        toml: keys of ``identity`` whose value is a TOML document, compared setting by
            setting.
        defaults: an identity made with the default settings: a setting missing from
            the folder's identity matches where it is asked at this default.
        hint: added to the error when the settings differ (how to resume).

    Raises:
        ``error``: ``out`` is a file; holds something that is not a folder of this
            kind; its marker is damaged; or it was made with another identity (the
            differing settings named, five at most).
    """
    out = Path(out)
    path = out / marker
    if out.exists() and not out.is_dir():
        raise error(f"--out {out} is a file, not an {kind} folder")
    if out.is_dir() and any(out.iterdir()):
        held = _held(path, identity["format"], kind, error)
        differ = differences(held, identity, noun, toml, defaults)
        if differ:
            raise error(
                f"{out} holds an {kind} made with other settings or data "
                f"({'; '.join(differ[:5])}); what it holds would not match. Use another "
                f"--out, or the same settings to resume it{hint}"
            )
        remove_stale(out)  # what a killed run left in it: its summaries, pictures, labels
        return
    out.mkdir(parents=True, exist_ok=True)
    for name, text in (files or {}).items():
        with atomic_file(out / name) as tmp:
            tmp.write_text(text)
    with atomic_file(path) as tmp:
        tmp.write_text(json.dumps(identity, indent=1) + "\n")


def _held(path: Path, fmt: str, kind: str, error) -> dict:
    """The identity a non-empty folder holds in ``path``."""
    refuse = (
        f"{path.parent} exists and is not an {kind} folder; refusing to write into it "
        "(choose another --out or remove it yourself)"
    )
    if not path.is_file():
        raise error(refuse)
    try:
        held = json.loads(path.read_text())
    except (OSError, ValueError):
        raise error(f"{path} is damaged: remove {path.parent} or choose another --out") from None
    if not isinstance(held, dict) or held.get("format") != fmt:
        raise error(refuse)
    return held


def differences(
    held: dict,
    wanted: dict,
    noun: str,
    toml: tuple[str, ...] = (),
    defaults: dict | None = None,
) -> list[str]:
    """``"key: <noun> has A, asked B"`` for every setting in which two identities
    differ (nested keys joined by dots; the values of ``toml`` keys read as TOML; a
    key ``held`` lacks matches where it is asked at its value in ``defaults``)."""
    a, b = _flat(held, toml), _flat(wanted, toml)
    d = _flat(defaults or {}, toml)
    return [
        f"{key}: {noun} has {a.get(key)!r}, asked {b.get(key)!r}"
        for key in sorted(a.keys() | b.keys())
        if a.get(key) != b.get(key) and not (key not in a and key in d and b[key] == d[key])
    ]


def _flat(table: dict, toml: tuple[str, ...], prefix: str = "") -> dict:
    out = {}
    for key, value in table.items():
        if key in toml and isinstance(value, str):
            try:
                value = tomllib.loads(value)
            except tomllib.TOMLDecodeError:
                value = {"(unreadable TOML)": value}
        if isinstance(value, dict):
            out.update(_flat(value, (), f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out
