"""Semantic classes of the scene (``assets/semantic_classes.csv``).

Each map part carries one of these; the cameras render them as segmentation labels.
Ids are stable: they are what a label image holds.
"""

from dataclasses import dataclass
from functools import cache
from pathlib import Path

import pandas as pd

from twin.core.errors import MapError
from twin.core.paths import asset

SEMANTIC_CSV = "semantic_classes.csv"


@dataclass(frozen=True)
class SemanticClass:
    class_id: int
    name: str
    color: tuple[int, int, int]  # RGB of the class in label visualisations


@cache
def semantic_classes(path: Path | None = None) -> tuple[SemanticClass, ...]:
    """The class table, ordered by id.

    Raises:
        MapError: the file lacks a column, repeats an id or a name, or has a colour
            outside 0..255.
    """
    path = Path(path) if path is not None else asset(SEMANTIC_CSV)
    frame = pd.read_csv(path)
    missing = {"class_id", "name", "r", "g", "b"} - set(frame.columns)
    if missing:
        raise MapError(f"{path.name}: missing column(s) {sorted(missing)}")
    if frame["class_id"].duplicated().any() or frame["name"].duplicated().any():
        raise MapError(f"{path.name}: class ids and names must be unique")
    rgb = frame[["r", "g", "b"]].to_numpy()
    if (rgb < 0).any() or (rgb > 255).any():
        raise MapError(f"{path.name}: colours must be in 0..255")
    frame = frame.sort_values("class_id")
    return tuple(
        SemanticClass(int(row.class_id), str(row.name), (int(row.r), int(row.g), int(row.b)))
        for row in frame.itertuples()
    )


def class_id(name: str) -> int:
    """Id of the semantic class ``name``.

    Raises:
        MapError: naming the unknown class and the known ones.
    """
    for semantic in semantic_classes():
        if semantic.name == name:
            return semantic.class_id
    known = [s.name for s in semantic_classes()]
    raise MapError(f"unknown semantic class {name!r}; known: {known}")
