"""Where Eclipse SUMO is: the ``eclipse-sumo`` package ships its tools (``sumo``,
``netconvert``), which the twin runs as processes (the SUMO export, SUMO-made test
data, the benchmark against SUMO)."""

import subprocess
from functools import cache
from pathlib import Path

from twin.core.errors import TwinError


class SumoMissing(TwinError):
    """Eclipse SUMO is not installed."""


def sumo_home() -> Path:
    """SUMO's home (the ``eclipse-sumo`` package).

    Raises:
        SumoMissing: it is not installed.
    """
    try:
        import sumo
    except ImportError:
        raise SumoMissing("this needs Eclipse SUMO: python3 -m pip install eclipse-sumo") from None
    return Path(sumo.SUMO_HOME)


def sumo_tool(name: str) -> Path:
    """The path of SUMO's tool ``name`` (``sumo``, ``netconvert``).

    Raises:
        SumoMissing: SUMO is not installed, or this installation lacks the tool.
    """
    path = sumo_home() / "bin" / name
    if not path.is_file():
        raise SumoMissing(f"Eclipse SUMO at {path.parent.parent} has no {name}")
    return path


@cache
def sumo_version() -> str:
    """The version of SUMO's ``sumo`` (``1.28.0``), as its ``--version`` states it.

    Raises:
        SumoMissing: SUMO is not installed, or its ``sumo`` does not run.
    """
    path = sumo_tool("sumo")
    done = subprocess.run([str(path), "--version"], capture_output=True, text=True, check=False)
    words = done.stdout.splitlines()[0].split() if done.stdout else []
    if done.returncode != 0 or len(words) < 4 or words[:3] != ["Eclipse", "SUMO", "sumo"]:
        raise SumoMissing(f"{path} --version did not state a version (exit {done.returncode})")
    return words[3]
