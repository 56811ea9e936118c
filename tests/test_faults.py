"""Faults of the machine and of the data, command by command: a read-only target, a full
disk, a cache that cannot be written, a truncated or corrupt input of every format the
twin reads, a kill in the middle of a write, and two commands at once.

Each fault a user can fix ends in exit status 2 and one line on stderr that names the
path and the cause, with no traceback, and leaves every earlier output as it was, byte
for byte. The machine's faults are injected where Python touches the file system (the
twin's writers all make their folders and commit their files there): a read-only target
refuses every folder, file and rename in it; a full disk refuses writing a file and
committing a finished one (renaming it from its temporary name)."""

import builtins
import errno
import gzip
import hashlib
import io
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.conftest import KERNEL_CACHE
from tests.twin.cosim.scenes import EGO_X, T0, make_store, vehicle
from twin.calibration.calibrate import CALIBRATION, FITS
from twin.cli import EXIT_USER_ERROR, main

ROOT = Path(__file__).resolve().parents[1]
#: The environment of the commands run as processes: this checkout's twin.
ENV = {**os.environ, "PYTHONPATH": str(ROOT), **KERNEL_CACHE}
#: How the one line names each fault's cause.
CAUSE = {errno.EROFS: "read-only", errno.ENOSPC: "no space left", errno.EACCES: "permission"}
SCENE = [vehicle(1, -2, EGO_X, 20.0), vehicle(2, -3, EGO_X + 40.0, 22.0)]
WHEN = "2022-11-30T06:45:50-06:00"


def digest(root: Path) -> dict[str, str]:
    """The sha256 of every file under ``root`` (hidden ones too), by relative path."""
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(Path(root).rglob("*"))
        if p.is_file()
    }


class Fault:
    """The file system under ``root`` failing with ``code``, as Python sees it.

    ``EROFS`` (a read-only target) or ``EACCES`` (no permission): no folder, file or
    rename can be made in it.
    ``ENOSPC`` (a full disk): folders and files can be made, but writing to a file fails
    as a real full disk's ``write`` does (an error that names no file), and no finished
    file is committed (renamed from a writer's temporary name).
    Lock files are exempt: they exist already, and opening one writes nothing.
    """

    def __init__(self, monkeypatch, root: Path, code: int):
        self.root, self.code = Path(root).resolve(), code
        real_open, real_mkdir = builtins.open, os.mkdir
        real_rename, real_replace = os.rename, os.replace

        def inside(path) -> bool:
            if isinstance(path, int) or str(path).endswith(".lock"):
                return False
            try:
                Path(os.path.abspath(path)).relative_to(self.root)
            except ValueError:
                return False
            return True

        def refuse(path):
            raise OSError(code, os.strerror(code), str(path))

        def open_(file, mode="r", *args, **kwargs):
            if not (inside(file) and any(c in mode for c in "wax+")):
                return real_open(file, mode, *args, **kwargs)
            if code != errno.ENOSPC:
                refuse(file)
            return _Full(real_open(file, mode, *args, **kwargs), code)

        def mkdir(path, *args, **kwargs):
            if code != errno.ENOSPC and inside(path):
                if os.path.exists(path):
                    raise FileExistsError(errno.EEXIST, os.strerror(errno.EEXIST), str(path))
                refuse(path)
            return real_mkdir(path, *args, **kwargs)

        def moves(real):
            def move(src, dst, *args, **kwargs):
                committing = ".partial-" in Path(src).name
                if inside(dst) and (code != errno.ENOSPC or committing):
                    refuse(dst)
                return real(src, dst, *args, **kwargs)

            return move

        monkeypatch.setattr(builtins, "open", open_)
        monkeypatch.setattr(io, "open", open_)
        monkeypatch.setattr(os, "mkdir", mkdir)
        monkeypatch.setattr(os, "rename", moves(real_rename))
        monkeypatch.setattr(os, "replace", moves(real_replace))


class _Full:
    """A file on a full disk: it opens, and every write fails without naming it."""

    def __init__(self, file, code: int):
        self._file, self._code = file, code

    def write(self, data):
        raise OSError(self._code, os.strerror(self._code))

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._file.close()

    def __getattr__(self, name):
        return getattr(self._file, name)


def assert_one_line(capsys, *naming: str) -> str:
    """The command's stderr is one ``twin: error:`` line naming each of ``naming``."""
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("twin: error: "), err
    assert "Traceback" not in err
    for name in naming:
        assert name in lines[0], (name, lines[0])
    return lines[0]


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """The two-vehicle store, with a run folder of it beside (``export`` reads it)."""
    store = make_store(tmp_path_factory.mktemp("faults"), SCENE)
    assert main(_run_args(store.path, store.path.parent / "run")) == 0
    return store


def _run_args(data: Path, out: Path) -> list[str]:
    return [
        "run", "--data", str(data), "--road", "westbound", "--lane", "-2",
        "--x", str(EGO_X), "--time", WHEN, "--duration", "2", "--world", "kinematic",
        "--out", str(out), "--quiet",
    ]  # fmt: skip


def writer(command: str, where: Path, scene, wave) -> tuple[list[str], Path]:
    """A command that writes, as its arguments and the output it writes into ``where``,
    on the stores ``scene`` (two vehicles, with a run folder beside it) and ``wave``
    (seven minutes of preset B)."""
    if command == "run":
        return _run_args(scene.path, where / "run"), where / "run"
    if command == "bench report":
        lines = where.parent / "lines.jsonl"
        lines.write_text(json.dumps({"bench": "query", "snapshot_median_us": 30.0}) + "\n")
        out = where / "benchmarks.md"
        return ["bench", "report", str(lines), "--lines", str(where / "b.jsonl"), "--out",
                str(out)], out  # fmt: skip
    names = {"data ingest": "store", "data synth": "a.json", "data plot": "ts.png",
             "data waves": "waves", "render": "f.png", "eval": "eval", "dataset": "dataset",
             "map build": "map", "map export": "i24.xodr", "map preview": "map.png",
             "export": "sumo", "train": "train"}  # fmt: skip
    out = where / names[command]
    argv = {
        "data ingest": ["data", "ingest", str(scene.path.parent / "day.json"), "--quiet"],
        "data synth": ["data", "synth", "--preset", "A", "--minutes", "0.5", "--quiet"],
        "data plot": ["data", "plot", str(wave.path), "--start", WHEN, "--minutes", "1"],
        "data waves": ["data", "waves", str(wave.path), "--road", "westbound", "--quiet"],
        "render": ["render", "--data", str(scene.path), "--set", "road=westbound",
                   "--set", "lane=-2", "--set", f"x={EGO_X}", "--set", f"time={T0}"],
        "eval": ["eval", "--data", str(wave.path), "--episodes", "1", "--duration", "5",
                 "--congested-share", "0", "--behaviour", "paper", "--world", "kinematic",
                 "--workers", "1", "--quiet"],
        "dataset": ["dataset", "--data", str(wave.path), "--episodes", "1",
                    "--frames-per-episode", "1", "--workers", "1", "--quiet",
                    "--set", 'sampling.roads=["westbound"]'],
        "map build": ["map", "build"],
        "map export": ["map", "export"],
        "map preview": ["map", "preview"],
        "export": ["export", str(scene.path.parent / "run"), "--format", "sumo"],
        "train": ["train", "--data", str(wave.path), "--iterations", "1", "--directions", "1",
                  "--top", "1", "--episodes", "1", "--duration", "5", "--workers", "1",
                  "--quiet"],
    }[command]  # fmt: skip
    return [*argv, "--out", str(out)], out


#: Every command that writes a file or a folder.
WRITERS = ("bench report", "data ingest", "data plot", "data synth", "data waves", "dataset",
           "eval", "export", "map build", "map export", "map preview", "render", "run",
           "train")  # fmt: skip


@pytest.mark.parametrize("command", WRITERS)
@pytest.mark.parametrize("code", [errno.EROFS, errno.ENOSPC], ids=["read-only", "full disk"])
def test_a_write_the_machine_refuses_is_one_line_and_keeps_the_earlier_output(
    command, code, scene, wave_store, tmp_path, monkeypatch, capsys
):
    where = tmp_path / "out"
    argv, out = writer(command, where, scene, wave_store)
    assert main(argv) == 0  # the earlier output
    capsys.readouterr()
    before = digest(where)
    with monkeypatch.context() as patch:
        Fault(patch, where, code)
        assert main(argv) == EXIT_USER_ERROR
    line = assert_one_line(capsys, str(out.parent), CAUSE[code])
    assert ".partial-" not in line  # the path the user gave, not a temporary one
    assert digest(where) == before


@pytest.mark.slow  # a whole calibration (about 12 s) before the write it refuses
def test_calibrate_on_a_read_only_store_keeps_the_store(wave_store, tmp_path, monkeypatch, capsys):
    store = tmp_path / "store"
    shutil.copytree(wave_store.path, store)
    before = digest(store)
    with monkeypatch.context() as patch:
        Fault(patch, store, errno.EROFS)
        assert main(["calibrate", str(store)]) == EXIT_USER_ERROR
    assert_one_line(capsys, str(store), "read-only")
    assert digest(store) == before


def test_a_cache_that_cannot_be_written_is_named_with_the_fix(scene, tmp_path, monkeypatch, capsys):
    """A run on a day file ingests it into the cache first (as the embedded data and the
    map are built there): the cache's fault is named with the variable that moves it."""
    cache = tmp_path / "cache"
    monkeypatch.setenv("I24_TWIN_CACHE", str(cache))
    argv = _run_args(scene.path, tmp_path / "run")
    argv[argv.index("--data") + 1] = str(scene.path.parent / "day.json")
    with monkeypatch.context() as patch:
        Fault(patch, cache, errno.EACCES)
        assert main(argv) == EXIT_USER_ERROR
    assert_one_line(capsys, str(cache), "permission denied", "I24_TWIN_CACHE")
    assert not (tmp_path / "run").exists()


# -- inputs that are truncated or corrupt ------------------------------------------------


def _day(tmp_path, docs=SCENE) -> bytes:
    return json.dumps(docs).encode()


@pytest.mark.parametrize(
    ("name", "content", "says"),
    [
        ("cut.json", lambda raw: raw[: len(raw) // 2], "malformed or truncated JSON"),
        ("cut.json.gz", lambda raw: gzip.compress(raw)[:-40], "truncated or corrupt"),
        ("noise.json.gz", lambda raw: b"\x1f\x8b" + bytes(range(200)), "truncated or corrupt"),
        ("none.json", lambda raw: b'[{"_id": 1}, {"x_position": []}]', "no valid I-24 MOTION"),
    ],
)
def test_a_bad_day_file_is_named_and_the_store_at_out_is_kept(
    name, content, says, scene, tmp_path, capsys
):
    out = tmp_path / "store"
    shutil.copytree(scene.path, out)
    before = digest(out)
    day = tmp_path / name
    day.write_bytes(content(_day(tmp_path)))
    assert main(["data", "ingest", str(day), "--out", str(out), "--quiet"]) == EXIT_USER_ERROR
    assert_one_line(capsys, str(day), says)
    assert digest(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([name, "store"])


@pytest.mark.parametrize(
    ("damage", "names"),
    [
        ("samples_westbound.parquet", "samples_westbound.parquet"),
        ("trajectories.parquet", "trajectories.parquet"),
        ("metadata.json", "metadata.json"),
        ("calibration.json", "calibration.json"),
    ],
)
@pytest.mark.parametrize("command", ["info", "run"])
def test_a_damaged_store_is_named_by_the_file(damage, names, command, scene, tmp_path, capsys):
    store = tmp_path / "store"
    shutil.copytree(scene.path, store)
    path = store / damage
    if damage == "calibration.json":
        path.write_text('{"format": "i24-twin-calibration", "roads": {')
    elif damage == "metadata.json" and command == "run":  # JSON, but not the store's
        path.write_text("[]")
    else:
        raw = path.read_bytes()
        path.write_bytes(raw[: len(raw) // 2])
    before = digest(store)
    argv = ["data", "info", str(store)] if command == "info" else _run_args(store, tmp_path / "run")
    assert main(argv) == EXIT_USER_ERROR
    assert_one_line(capsys, str(store / names))
    assert digest(store) == before


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ('road = "westbound"\nlane = ', "run.toml"),
        ("\udcff", "not a TOML text file (not UTF-8"),
        ("lane = -7\n", "lane"),
        ("[traffic]\nhov_share = nan\n", "hov_share"),
    ],
)
def test_a_bad_config_file_is_named(text, says, scene, tmp_path, capsys):
    config = tmp_path / "run.toml"
    config.write_bytes(text.encode("utf-8", "surrogateescape"))
    argv = [*_run_args(scene.path, tmp_path / "run"), "--config", str(config)]
    assert main(argv) == EXIT_USER_ERROR
    assert_one_line(capsys, str(config), says)
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("damage", ["eval.json", "results"])
def test_a_damaged_evaluation_folder_is_named_and_kept(damage, scene, wave_store, tmp_path, capsys):
    argv = writer("eval", tmp_path, scene, wave_store)[0]
    out = tmp_path / "eval"
    assert main(argv) == 0
    capsys.readouterr()
    if damage == "eval.json":
        damaged = out / "eval.json"
        damaged.write_text('{"format": "i24-twin-eval", "conf')
    else:
        (damaged,) = (out / "results").glob("*.json")
        damaged.write_text(damaged.read_text()[:20])
    before = digest(out)
    assert main(argv) == EXIT_USER_ERROR
    assert_one_line(capsys, str(damaged))
    assert digest(out) == before


def test_a_time_in_milliseconds_is_named_as_such(scene, tmp_path, capsys):
    argv = _run_args(scene.path, tmp_path / "run")
    argv[argv.index("--time") + 1] = "1669812350000"
    assert main(argv) == EXIT_USER_ERROR
    assert_one_line(capsys, "--time", "1669812350000", "milliseconds", "1669812350.000")
    # the same time given as a setting, not as the option
    del argv[argv.index("--time") : argv.index("--time") + 2]
    assert main([*argv, "--set", "time=1669812350000"]) == EXIT_USER_ERROR
    assert_one_line(capsys, "1669812350000", "milliseconds", "1669812350.000")


def test_calibrating_a_store_without_trajectories_says_why(tmp_path, capsys):
    from twin.calibration.calibrate import calibrate
    from twin.core.errors import TwinError
    from twin.data.store import TrajectoryStore

    store = make_store(tmp_path / "one", SCENE)
    meta = json.loads((store.path / "metadata.json").read_text())
    empty = TrajectoryStore(store.path)
    empty.metadata = {**meta, "roads": {}}
    with pytest.raises(TwinError, match="holds no trajectories"):
        calibrate(empty)


# -- progress bars and the behaviour a calibration chooses ------------------------------------


@pytest.mark.slow  # three commands in new processes, a calibration among them (20 s)
def test_no_progress_bar_is_written_into_a_log(wave_store, tmp_path):
    """stderr to a file (a log): the commands that show progress on a terminal write
    none of it there."""
    log = tmp_path / "log.txt"
    store = tmp_path / "store"
    shutil.copytree(wave_store.path, store)
    commands = (
        ["calibrate", str(store)],
        ["data", "waves", str(store), "--road", "westbound", "--out", str(tmp_path / "w")],
        _run_args(store, tmp_path / "run")[:-1],  # without --quiet
    )
    for argv in commands:
        with open(log, "w") as err:
            done = subprocess.run([sys.executable, "-m", "twin", *argv], stderr=err, env=ENV,
                                  stdout=subprocess.DEVNULL, cwd=tmp_path, check=False)  # fmt: skip
        text = log.read_text()
        assert done.returncode == 0, text
        assert "\r" not in text and "it/s" not in text and "%|" not in text, text


def test_a_run_says_when_a_calibration_chose_its_behaviour(
    wave_store, calibrated_wave_store, tmp_path, capsys
):
    store = tmp_path / "store"
    shutil.copytree(wave_store.path, store)
    argv = _run_args(store, tmp_path / "run")
    argv[argv.index("--lane") + 1] = "-1"
    argv[argv.index("--x") + 1] = "700"
    assert main(argv) == 0
    assert "auto chose" not in capsys.readouterr().out
    for name in (CALIBRATION, FITS):  # what `twin calibrate` writes (the session's)
        shutil.copy(calibrated_wave_store.path / name, store / name)
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "auto chose calibrated: the data hold a calibration (calibration.json made" in out
    assert "--behaviour paper drives as the paper does" in out


# -- a kill in the middle of a write, then the same command again ------------------------------


KILLED = ("data ingest", "dataset", "eval", "map build")


def _killed_args(command: str, where: Path, wave) -> list[str]:
    if command == "data ingest":
        return ["data", "ingest", str(wave.path.parent / "wave.json"), "--out", str(where / "s")]
    if command == "map build":
        return ["map", "build", "--out", str(where / "map")]
    return writer(command, where, wave, wave)[0]


def _kill_while_writing(twin: list[str], where: Path) -> None:
    """Start ``twin`` and kill it once a writer's temporary file or folder is there."""
    process = subprocess.Popen(twin, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=ENV)
    deadline = time.monotonic() + 120.0
    while not any(where.rglob(".*.partial-*")):
        assert process.poll() is None, "it finished before anything was written"
        assert time.monotonic() < deadline, "nothing was written in 120 s"
        time.sleep(0.02)
    process.send_signal(signal.SIGKILL)
    process.wait()


@pytest.mark.slow
@pytest.mark.parametrize("command", KILLED)
def test_a_killed_write_leaves_the_earlier_output_and_the_rerun_completes(
    command, scene, wave_store, tmp_path
):
    """Killed while it writes: an output written whole before is as it was (ingest, map
    build); a resumable folder (eval, dataset) resumes. Then the same command completes
    and nothing of the killed writer is left anywhere."""
    argv = _killed_args(command, tmp_path, wave_store)
    twin = [sys.executable, "-m", "twin", *argv]
    out = Path(argv[argv.index("--out") + 1])
    resumable = command in ("eval", "dataset")
    if not resumable:
        assert subprocess.run(twin, capture_output=True, env=ENV, check=False).returncode == 0
    before = digest(out) if out.exists() else None
    _kill_while_writing(twin, tmp_path)
    if not resumable:
        assert digest(out) == before
    done = subprocess.run(twin, capture_output=True, text=True, env=ENV, check=False)
    assert done.returncode == 0, done.stderr
    assert not list(tmp_path.rglob(".*.partial-*")), "a killed writer's leftovers remain"
    assert not list(tmp_path.rglob(".*.old-*"))
    if command == "data ingest":
        assert digest(out) == before  # the same inputs give the same bytes


# -- two commands at once ----------------------------------------------------------------


@pytest.mark.slow
def test_two_first_runs_at_once_build_the_cache_once(scene, tmp_path):
    """Both build the map into a fresh cache and ingest the same day file there: one
    builds while the other waits, and both succeed."""
    env = {**ENV, "I24_TWIN_CACHE": str(tmp_path / "cache")}
    day = str(scene.path.parent / "day.json")
    runs = []
    for k in range(2):
        argv = _run_args(scene.path, tmp_path / f"run{k}")
        argv[argv.index("--data") + 1] = day
        runs.append(subprocess.Popen([sys.executable, "-m", "twin", *argv], env=env,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True))  # fmt: skip
    results = [run.communicate() for run in runs]
    assert [run.returncode for run in runs] == [0, 0], results
    # one waited for the other's build (of the day file's store, or of the map)
    assert any("waiting for another twin process to finish" in err for _, err in results)
    cache = sorted(p.name for p in (tmp_path / "cache").iterdir() if not p.name.startswith("."))
    assert len([n for n in cache if n.startswith("map-")]) == 1
    assert len([n for n in cache if n.startswith("store-")]) == 1
    a, b = (digest(tmp_path / f"run{k}") for k in range(2))
    assert a["trajectories.parquet"] == b["trajectories.parquet"]


@pytest.mark.slow
def test_a_run_waits_while_another_process_builds_what_it_needs(scene, tmp_path):
    """The cache entry of a day file is being built by another process (the lock held
    here): the run says it waits, waits, and goes on once the other has finished."""
    from twin.core.locks import build_lock

    cache, day = tmp_path / "cache", scene.path.parent / "day.json"
    entry = cache / f"store-{hashlib.sha256(day.read_bytes()).hexdigest()[:16]}"
    argv = _run_args(day, tmp_path / "run")
    log = tmp_path / "stderr.txt"
    with build_lock(entry), open(log, "w") as err:
        run = subprocess.Popen([sys.executable, "-m", "twin", *argv], stderr=err,
                               stdout=subprocess.DEVNULL,
                               env={**ENV, "I24_TWIN_CACHE": str(cache)})  # fmt: skip
        deadline = time.monotonic() + 60.0
        while "waiting" not in log.read_text() and time.monotonic() < deadline:
            time.sleep(0.2)
        time.sleep(1.0)
        assert run.poll() is None, log.read_text()  # still waiting
    # then it goes on: with its own empty cache it builds the map and compiles every
    # kernel (a hang guard, not a speed test: that took 2 to 3.5 minutes on a 2-core
    # machine that a full suite shares)
    assert run.wait(timeout=360) == 0, log.read_text()
    assert log.read_text().startswith(f"waiting for another twin process to finish {entry}")
    assert (tmp_path / "run" / "metrics.json").is_file()


@pytest.mark.parametrize("command", ["eval", "dataset"])
def test_a_second_command_on_the_same_out_is_refused(command, scene, wave_store, tmp_path, capsys):
    from twin.core.locks import output_lock

    argv, out = writer(command, tmp_path, scene, wave_store)
    assert main(argv) == 0  # a folder another command is now extending
    capsys.readouterr()
    before = digest(out)
    with output_lock(out, f"twin {command}"):  # as that command, running now, holds it
        assert main(argv) == EXIT_USER_ERROR
    line = assert_one_line(capsys, str(out), f"being written by twin {command} (pid")
    assert "choose another --out" in line
    assert digest(out) == before
    assert main(argv) == 0  # once the other has finished
