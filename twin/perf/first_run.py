"""``twin bench first-run``: a new user's first ``twin run``, as on a fresh machine.

Each repeat runs the console script ``twin run`` twice in a new process with an empty
cache folder (``$I24_TWIN_CACHE``, no ``$NUMBA_CACHE_DIR``): the first builds the
embedded data and the map and compiles the kernels (in its second process,
:mod:`twin.runners.precompile`), the second finds them all cached. The install is not
timed."""

import os
import re
import shutil
import subprocess
import sysconfig
import tempfile
import time
from pathlib import Path

from twin.perf.common import median

COMPILED = re.compile(r"^compiled the kernels in ([\d.]+) s", re.MULTILINE)
REAL_TIME = re.compile(r"^simulated [\d.]+ s in [\d.]+ s: ([\d.]+) x real time", re.MULTILINE)
TARGETS = {"first_run_s": "<= 45", "compile_s": "<= 30"}


def twin_script() -> str:
    """The ``twin`` console script of this interpreter (as ``pip install`` made it)."""
    script = Path(sysconfig.get_path("scripts")) / "twin"
    found = str(script) if script.exists() else shutil.which("twin")
    if found is None:
        raise FileNotFoundError("the console script `twin` is not installed: pip install -e .")
    return found


def first_run_bench(*, world: str = "physics", repeats: int = 3) -> dict:
    """[s] wall time of a first ``twin run`` on a fresh cache (``first_run_s``), of its
    kernels' compilation (``compile_s``, as the run reports it) and of a second run
    (``warm_run_s``), with each run's real-time factor; medians over ``repeats``.

    Raises:
        RuntimeError: a run failed (its output's last lines are in the message).
    """
    twin = twin_script()
    figures: dict[str, list[float]] = {
        key: []
        for key in (
            "first_run_s",
            "compile_s",
            "warm_run_s",
            "first_real_time_factor",
            "warm_real_time_factor",
        )
    }
    for _ in range(repeats):
        with tempfile.TemporaryDirectory(prefix="twin-first-run-") as root:
            env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
            env |= {"I24_TWIN_CACHE": str(Path(root) / "cache"),
                    "MPLCONFIGDIR": str(Path(root) / "matplotlib")}  # fmt: skip
            for name in ("first", "warm"):
                start = time.perf_counter()
                done = subprocess.run(
                    [twin, "run", "--world", world, "--quiet", "--out", str(Path(root) / name)],
                    env=env, cwd=root, capture_output=True, text=True, stdin=subprocess.DEVNULL,
                )  # fmt: skip
                wall = time.perf_counter() - start
                if done.returncode != 0:
                    tail = (done.stdout + done.stderr).strip().splitlines()[-5:]
                    raise RuntimeError(f"the {name} twin run failed: " + " | ".join(tail))
                figures["first_run_s" if name == "first" else "warm_run_s"].append(wall)
                factor = REAL_TIME.search(done.stdout)
                figures[f"{name}_real_time_factor"].append(
                    float(factor.group(1)) if factor else float("nan")
                )
                if name == "first":
                    compiled = COMPILED.search(done.stdout)
                    figures["compile_s"].append(
                        float(compiled.group(1)) if compiled else float("nan")
                    )
    out = {key: round(median(values), 2) for key, values in figures.items()}
    return {"world": world, "repeats": repeats, **out, "targets": dict(TARGETS)}
