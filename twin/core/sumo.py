"""Where Eclipse SUMO is: the ``eclipse-sumo`` package ships its tools (``sumo``,
``netconvert``), which the twin runs as processes (the SUMO export, SUMO-made test
data, the benchmark against SUMO)."""

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
