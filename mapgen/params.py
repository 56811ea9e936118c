"""The map's geometry parameters, read from ``assets/map.toml`` into frozen dataclasses.

Every length is in metres. What the design fixes (``docs/design.md``: lane width, lane
count, the yellow edge line 12 ft from the median centre line) comes from
:mod:`twin.core.i24` and is not repeated here.
"""

import tomllib
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, get_type_hints

from twin.core.errors import MapError
from twin.core.paths import asset

MAP_TOML = "map.toml"


@dataclass(frozen=True)
class Extent:
    margin: float  # [m] map beyond each end of the segment (>= 400)

    def __post_init__(self):
        if self.margin < 400.0:
            raise MapError(f"extent.margin must be >= 400 m, got {self.margin}")


@dataclass(frozen=True)
class Alignment:
    fit_mm: tuple[float, float]  # [mi] the posts that fix the bearing

    def __post_init__(self):
        lo, hi = self.fit_mm
        if not lo < hi:
            raise MapError(f"alignment.fit_mm must be increasing, got {self.fit_mm}")


@dataclass(frozen=True)
class CrossSection:
    outer_shoulder: float  # [m] paved right shoulder beyond lane -4


@dataclass(frozen=True)
class Barrier:
    profile_y: tuple[float, ...]  # [m] half profile, from the centre line outward
    profile_z: tuple[float, ...]  # [m] above the road surface

    def __post_init__(self):
        if len(self.profile_y) != len(self.profile_z) or len(self.profile_y) < 3:
            raise MapError("barrier.profile_y and profile_z need the same length (>= 3)")
        if self.profile_z[-1] != 0.0 or self.profile_y[0] != 0.0:
            raise MapError("barrier profile must start on the centre line and end on the road")


@dataclass(frozen=True)
class Markings:
    width: float
    lift: float  # [m] above the pavement
    dash: float
    gap: float
    double_gap: float
    diamond_length: float
    diamond_width: float
    diamond_every: int  # profile steps between diamonds

    def __post_init__(self):
        if not 0.0 < self.lift <= 0.02:
            raise MapError(f"markings.lift must be in (0, 0.02] m, got {self.lift}")
        if self.diamond_every < 1:
            raise MapError(f"markings.diamond_every must be >= 1, got {self.diamond_every}")


@dataclass(frozen=True)
class Terrain:
    width: float
    columns: tuple[float, ...]  # [m] grid offsets beyond the shoulder edge, from 0
    ditch_offset: tuple[float, ...]
    ditch_depth: tuple[float, ...]
    relief: float  # [m] standard deviation of the natural ground
    relief_ramp: float
    wavelength: float
    octaves: int

    def __post_init__(self):
        if self.columns[0] != 0.0 or any(
            b <= a for a, b in zip(self.columns, self.columns[1:], strict=False)
        ):
            raise MapError("terrain.columns must start at 0 and increase")
        if self.columns[-1] != self.width:
            raise MapError("terrain.columns must end at terrain.width")
        if len(self.ditch_offset) != len(self.ditch_depth) or self.ditch_depth[0] != 0.0:
            raise MapError("terrain.ditch_offset/ditch_depth: same length, depth 0 at the edge")
        if self.ditch_depth[-1] != 0.0:
            raise MapError("terrain.ditch_depth must come back to 0")


@dataclass(frozen=True)
class Poles:
    height: float
    base_radius: float
    top_radius: float
    head: tuple[float, float, float]
    min_offset: float


@dataclass(frozen=True)
class Posts:
    spacing_mi: float
    offset: float
    height: float
    plate: tuple[float, float]
    size: float


@dataclass(frozen=True)
class Overpass:
    landmarks: tuple[str, str]  # eastbound and westbound landmark names
    deck_width: float
    deck_depth: float
    clearance: float  # [m] above the highest road point below the deck
    parapet_height: float
    parapet_width: float
    pier_size: float
    pier_spacing: float
    median_pier_size: float
    outer_pier_offset: float
    abutment_offset: float
    abutment_depth: float

    def __post_init__(self):
        if self.clearance < 4.9:
            raise MapError(f"overpass.clearance must be >= 4.9 m (16 ft), got {self.clearance}")


@dataclass(frozen=True)
class Part:
    semantic_class: str
    color: tuple[float, float, float, float]  # RGBA in 0..1


@dataclass(frozen=True)
class MapParams:
    extent: Extent
    alignment: Alignment
    cross_section: CrossSection
    barrier: Barrier
    markings: Markings
    terrain: Terrain
    poles: Poles
    posts: Posts
    overpass: Overpass
    parts: dict[str, Part]


def load_params(path: Path | None = None) -> MapParams:
    """Parse ``assets/map.toml`` (or ``path``).

    Raises:
        MapError: naming the file and the table or key that is missing, unknown,
            of the wrong type or out of range.
    """
    path = Path(path) if path is not None else asset(MAP_TOML)
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as error:
        raise MapError(f"{path}: not valid TOML ({error})") from error
    try:
        parts = data.pop("parts", None)
        if not isinstance(parts, dict) or not parts:
            raise MapError("no [parts.*] tables")
        tables = {
            f.name: _table(get_type_hints(MapParams)[f.name], data.get(f.name), f.name)
            for f in fields(MapParams)
            if f.name != "parts"
        }
        unknown = set(data) - set(tables)
        if unknown:
            raise MapError(f"unknown table(s) {sorted(unknown)}")
        renamed = {
            name: {"semantic_class": t.get("class"), **{k: v for k, v in t.items() if k != "class"}}
            for name, t in parts.items()
        }
        return MapParams(
            **tables,
            parts={name: _table(Part, t, f"parts.{name}") for name, t in renamed.items()},
        )
    except MapError as error:
        raise MapError(f"{path}: {error}") from None


def _table(cls, values: Any, name: str):
    if not isinstance(values, dict):
        raise MapError(f"missing table [{name}]")
    hints = get_type_hints(cls)
    missing = [f.name for f in fields(cls) if f.name not in values]
    unknown = set(values) - set(hints)
    if missing or unknown:
        raise MapError(f"[{name}]: missing {missing}, unknown {sorted(unknown)}")
    kwargs = {}
    for key, value in values.items():
        kind = hints[key]
        try:
            if kind is float:
                kwargs[key] = _number(value)
            elif kind is int:
                kwargs[key] = _integer(value)
            elif kind is str:
                kwargs[key] = _string(value)
            elif getattr(kind, "__origin__", None) is tuple:
                element = kind.__args__[0]
                items = tuple(_string(v) if element is str else _number(v) for v in value)
                if len(kind.__args__) == 2 and kind.__args__[1] is Ellipsis:
                    kwargs[key] = items
                elif len(items) != len(kind.__args__):
                    raise TypeError(f"{len(kind.__args__)} items, got {len(items)}")
                else:
                    kwargs[key] = items
            else:
                raise TypeError(f"unsupported type {kind}")
        except TypeError as error:
            raise MapError(f"[{name}] {key} = {value!r}: {error}") from None
    return cls(**kwargs)


def _number(value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise TypeError("expected a number")
    if value != value or value in (float("inf"), float("-inf")):
        raise TypeError("expected a finite number")
    return float(value)


def _integer(value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise TypeError("expected an integer")
    return value


def _string(value: Any) -> str:
    if not isinstance(value, str):
        raise TypeError("expected a string")
    return value
