"""A new user's first run: the console script on a fresh cache, as after ``pip install -e .``.

The commands run in a subprocess whose interpreter cannot import the test extra's
packages (a ``sitecustomize`` on ``PYTHONPATH`` makes them missing, as they are after
``pip install -e .``), with an empty ``$I24_TWIN_CACHE`` and an empty matplotlib
configuration folder. Their output may hold only the twin's own lines: no traceback,
no library's warning, no pybullet banner or GL driver lines.
"""

import os
import re
import subprocess
import sys
import tomllib
from importlib.metadata import packages_distributions
from pathlib import Path

import pytest

from twin.perf.first_run import twin_script

ROOT = Path(__file__).resolve().parents[1]
NOISE = re.compile(  # what libraries print on their own: never part of the twin's output
    r"Traceback|falling back|pybullet build time|Warning|WARNING|warn\(|^pybullet:"
    r"|EGL|GL_[A-Z]+=|^ven = |^(Version|Vendor|Renderer) = |font cache",
    re.MULTILINE,
)
MAX_LINES = 40  # the bound on the first `twin run` (no progress bars: not a terminal)


def _normalized(name: str) -> str:
    return re.split(r"[<>=!~\[; ]", name, maxsplit=1)[0].lower().replace("_", "-")


def modules_of_the_test_extra() -> set[str]:
    """Top-level modules that only the ``test`` extra brings (not a dependency)."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    core = {_normalized(d) for d in project["dependencies"]}
    extra = {_normalized(d) for d in project["optional-dependencies"]["test"]} - core
    return {
        module
        for module, dists in packages_distributions().items()
        if extra & {_normalized(d) for d in dists}
    }


SITECUSTOMIZE = """\
import sys

MISSING = frozenset({modules!r})


class _NotInstalled:
    \"\"\"The test extra's packages, missing as after a plain `pip install -e .`.\"\"\"

    @staticmethod
    def find_spec(name, path=None, target=None):
        if name.partition(".")[0] in MISSING:
            raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)
        return None


sys.meta_path.insert(0, _NotInstalled())
"""


class FreshUser:
    """A working folder, an empty cache and an interpreter without the test extra."""

    def __init__(self, root: Path):
        self.cwd = root / "work"
        self.cwd.mkdir()
        hide = root / "site"
        hide.mkdir()
        self.missing = modules_of_the_test_extra()
        (hide / "sitecustomize.py").write_text(SITECUSTOMIZE.format(modules=sorted(self.missing)))
        self.env = {
            **{k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"},  # none yet
            "I24_TWIN_CACHE": str(root / "cache"),
            "MPLCONFIGDIR": str(root / "matplotlib"),
            "PYTHONPATH": os.pathsep.join(
                p for p in (str(hide), os.environ.get("PYTHONPATH", "")) if p
            ),
        }
        try:
            self.twin = twin_script()
        except FileNotFoundError as missing:
            pytest.fail(str(missing))

    def run(self, *args: str, timeout: float = 600.0) -> subprocess.CompletedProcess:
        return subprocess.run(
            [self.twin, *args],
            cwd=self.cwd,
            env=self.env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            timeout=timeout,
        )


def assert_clean(result: subprocess.CompletedProcess) -> list[str]:
    """The command succeeded and printed only the twin's own lines; returns them."""
    assert result.returncode == 0, result.stdout[-3000:]
    noise = sorted({m.group(0) for m in NOISE.finditer(result.stdout)})
    assert not noise, f"library noise {noise} in:\n{result.stdout[-3000:]}"
    return [line for line in result.stdout.splitlines() if line.strip()]


@pytest.fixture(scope="module")
def user(tmp_path_factory):
    return FreshUser(tmp_path_factory.mktemp("first_run"))


@pytest.fixture(scope="module")
def fresh(user):
    """The fresh user after their first ``twin run`` (which builds the data and the map)."""
    user.first = user.run("run")
    return user


def test_the_test_extra_is_missing_for_the_fresh_user(user):
    assert {"pytest", "pycocotools", "ray"} <= user.missing
    probe = subprocess.run(
        [sys.executable, "-c", "import scipy, trimesh, pybullet; import pycocotools"],
        env=user.env,
        capture_output=True,
        text=True,
    )
    assert probe.returncode == 1
    assert "No module named 'pycocotools'" in probe.stderr


@pytest.mark.slow
def test_the_first_twin_run_prints_only_the_twins_summary(fresh):
    lines = assert_clean(fresh.first)
    assert len(lines) <= MAX_LINES, "\n".join(lines)
    # the kernels compile in other processes while the data and the map are built,
    # said once, and timed on a line of their own
    assert lines[0].startswith("compiling the traffic core's kernels in the background")
    assert lines[1].startswith("building the embedded data")
    assert len([line for line in lines if line.startswith("compiled the kernels in")]) == 1
    assert "scenario B, behaviour paper, the ego driven by the traffic manager" in lines
    assert any(line.startswith("simulated 30.0 s") for line in lines)
    # it ends by listing what it wrote
    listed = lines[lines.index("wrote runs/B:") + 1 :]
    assert [line.split()[0] for line in listed] == [
        "config.toml", "trajectories.parquet", "metrics.json", "timespace.png", "boundary.png",
        "bev.png",
    ]  # fmt: skip
    assert (fresh.cwd / "runs" / "B" / "metrics.json").is_file()


@pytest.mark.slow
def test_the_first_run_bench_reads_what_the_first_run_prints(fresh):
    """``twin bench first-run`` times this run; its compile time and real-time factors
    are read from the lines the run prints."""
    from twin.perf.first_run import COMPILED, REAL_TIME

    compiled, factor = COMPILED.search(fresh.first.stdout), REAL_TIME.search(fresh.first.stdout)
    assert compiled and float(compiled.group(1)) > 0
    assert factor and float(factor.group(1)) > 0
    again = fresh.run("run", "--out", "again")  # the kernels are cached now: said nothing of
    assert not any("compil" in line for line in assert_clean(again))


@pytest.mark.slow
@pytest.mark.parametrize(
    "command",
    [
        "map build --out map",
        "map preview --out preview.png",
        "data info",
        "data plot --road westbound --minutes 2 --out ts.png",
        "render --t 5 --labels --out frame.png",
        "dataset --episodes 2 --frames-per-episode 1 --workers 2 --out ds",  # 2 spawned workers
    ],
)
def test_the_first_commands_print_only_the_twins_lines(fresh, command):
    assert_clean(fresh.run(*command.split()))


@pytest.mark.slow
def test_an_egl_frame_prints_no_gl_driver_lines(fresh):
    """EGL (the GPU where one is, else Mesa's llvmpipe): the driver's lines are dropped."""
    result = fresh.run("render", "--t", "5", "--set", "camera.renderer=egl", "--out", "egl.png")
    if result.returncode != 0 and not os.environ.get("CI"):
        pytest.skip(f"no working EGL here: {result.stdout.strip().splitlines()[-1:]}")
    lines = assert_clean(result)
    assert len(lines) == 1 and "(egl)" in lines[0]
