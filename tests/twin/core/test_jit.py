"""Where compiled kernels are cached (twin.core.jit): a folder named by a digest of
every module that defines kernels and of every twin module they import, so that a
change to a kernel's callee or to a constant it reads in another module compiles
afresh (Numba checks only the time stamp of a kernel's own file)."""

import os
import subprocess
import sys

import numba

from twin.core.jit import PACKAGE, kernel_sources, sources_digest


def _package(root):
    (root / "pkg").mkdir(parents=True)
    (root / "kern.py").write_text(
        "from twin.consts import LIMIT\nfrom twin.pkg import (\n    mod,\n)\n\n@kernel\n"
        "def f(x):\n    return min(x, LIMIT)\n"
    )
    (root / "consts.py").write_text("import twin.deep\nLIMIT = 2.0\n")
    (root / "deep.py").write_text("DEPTH = 3\n")
    (root / "pkg" / "__init__.py").write_text("")
    (root / "pkg" / "mod.py").write_text("G = 9.81\n")
    (root / "cli.py").write_text("from twin.kern import f  # uses kernels, defines none\n")
    return root


def test_the_sources_are_the_kernels_modules_and_what_they_import(tmp_path):
    root = _package(tmp_path / "twin")
    names = [p.relative_to(root).as_posix() for p in kernel_sources(root)]
    assert names == ["consts.py", "deep.py", "kern.py", "pkg/__init__.py", "pkg/mod.py"]


def test_the_digest_changes_with_a_callee_or_a_constant_and_not_with_the_rest(tmp_path):
    root = _package(tmp_path / "twin")

    def digest():
        return sources_digest(kernel_sources(root), root)

    first = digest()
    assert digest() == first  # the same sources, the same folder
    (root / "cli.py").write_text("# a change where no kernel looks\n")
    assert digest() == first
    (root / "deep.py").write_text("DEPTH = 4\n")  # imported by an import of a kernel's
    second = digest()
    assert second != first
    (root / "pkg" / "mod.py").write_text("G = 9.80665\n")
    assert digest() not in (first, second)


def test_the_twins_kernels_compile_into_the_folder_of_their_digest(tmp_path):
    names = {p.relative_to(PACKAGE).as_posix() for p in kernel_sources()}
    assert {"cosim/core/step.py", "cosim/core/handover.py", "physics/vehicle.py",
            "core/i24.py"} <= names  # fmt: skip
    key = sources_digest(kernel_sources())
    assert os.path.basename(numba.config.CACHE_DIR) == key
    code = "import numba, twin.core.jit; print(numba.config.CACHE_DIR)"
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert out.stdout.strip() == str(tmp_path / "numba" / key), out.stderr


def test_two_processes_saving_two_signatures_at_once_keep_both(tmp_path, monkeypatch):
    """Numba's cache index is read, given a new entry and written back: two compiles of
    one kernel's two signatures at once (two test workers, an evaluation's workers) both
    took the first free data file name, and one signature's machine code replaced the
    other's. Under the twin's lock the second save waits and takes the next name."""
    import threading
    import time

    from numba.core import caching

    read_index = caching.IndexDataCacheFile._load_index

    def slow_read(self):  # both saves read the index before either writes it
        index = read_index(self)
        time.sleep(0.3)
        return index

    monkeypatch.setattr(caching.IndexDataCacheFile, "_load_index", slow_read)

    def save(key):  # each as its own process would: its own cache file object
        caching.IndexDataCacheFile(str(tmp_path), "kern.f-7", "stamp").save(key, key * 100)

    savers = [threading.Thread(target=save, args=(key,)) for key in ("a", "b")]
    for saver in savers:
        saver.start()
    for saver in savers:
        saver.join()
    cache = caching.IndexDataCacheFile(str(tmp_path), "kern.f-7", "stamp")
    assert cache.load("a") == "a" * 100
    assert cache.load("b") == "b" * 100
    assert len(list(tmp_path.glob("*.nbc"))) == 2
