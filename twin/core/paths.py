"""Where the twin finds its shipped assets and keeps its cache."""

import os
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]
ASSETS_DIR = REPO_ROOT / "assets"


def cache_dir() -> Path:
    """The cache folder.

    ``$I24_TWIN_CACHE``, else ``$XDG_CACHE_HOME/i24-twin``, else ``~/.cache/i24-twin``.
    """
    if env := os.environ.get("I24_TWIN_CACHE"):
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "i24-twin"


def asset(name: str) -> Path:
    """Path of a shipped asset; raises FileNotFoundError naming it when the checkout lacks it."""
    path = ASSETS_DIR / name
    if not path.exists():
        raise FileNotFoundError(
            f"asset {name!r} not found at {path}; install i24-twin from a full checkout "
            "(pip install -e .) so that assets/ is beside the package"
        )
    return path
