"""What the twin computes, as SHA-256 digests: the reference a reorganisation must keep.

Each entry runs a command as a user would (``twin.cli.main``, or the Gymnasium env)
and digests its outputs:

* Parquet tables by content (column names, types and values, in order), not by file
  bytes: pyarrow writes its own version into the file, which a new release changes;
* text files (KITTI labels, COCO JSON, synthetic I-24 JSON) by their bytes;
* ``episodes.parquet`` of ``twin eval`` without its timing columns (wall-clock).

``python -m tests.golden.outputs`` prints the digests as JSON (to record them in
``hashes.json`` when a result is meant to change, in the commit that changes it).
"""

import hashlib
import json
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

HERE = Path(__file__).resolve().parent
RECORDED = HERE / "hashes.json"
#: Columns of ``episodes.parquet`` that hold wall-clock times, not results.
TIMING_COLUMNS = ("loop_s",)


def table_digest(path: Path, drop=()) -> str:
    """SHA-256 of a Parquet table's content: per column its name, type and values."""
    table = pq.read_table(path)
    digest = hashlib.sha256()
    for name in table.column_names:
        if any(name == d or name.endswith("_" + d) for d in drop):
            continue
        column = table.column(name)
        digest.update(f"{name}:{column.type}\n".encode())
        values = column.to_pylist() if not _numeric(column.type) else None
        if values is None:
            array = column.to_numpy(zero_copy_only=False)
            if array.dtype == object:
                raise TypeError(f"column {name} became an object array; digest it as a list")
            digest.update(np.ascontiguousarray(array).tobytes())
            digest.update(np.asarray(column.is_null()).tobytes())
        else:
            digest.update(json.dumps(values, sort_keys=True, default=str).encode())
    return digest.hexdigest()


def _numeric(kind) -> bool:
    import pyarrow as pa

    return pa.types.is_integer(kind) or pa.types.is_floating(kind)


def files_digest(paths) -> str:
    """SHA-256 of files' names (relative) and bytes, in sorted order."""
    digest = hashlib.sha256()
    for root, path in sorted(paths, key=lambda p: str(p[1].relative_to(p[0]))):
        digest.update(str(path.relative_to(root)).encode() + b"\n")
        digest.update(path.read_bytes())
    return digest.hexdigest()


def twin(command: str) -> None:
    """Run ``twin COMMAND`` as a user would (words split on spaces)."""
    from twin.cli import main

    code = main(command.split())
    if code != 0:
        raise RuntimeError(f"twin {command} exited with {code}")


def run_digests(work: Path) -> dict[str, str]:
    """``twin run --seed 3 --duration 10`` of A and B (paper), and one calibrated run."""
    out = {}
    for scenario in ("A", "B"):
        folder = work / f"run_{scenario}"
        twin(
            f"run --scenario {scenario} --seed 3 --duration 10 --behaviour paper --quiet "
            f"--out {folder}"
        )
        out[f"run_{scenario}_paper"] = table_digest(folder / "trajectories.parquet")
        out[f"run_{scenario}_paper_metrics"] = metrics_digest(folder / "metrics.json")
    return out


def calibrated_run_digest(work: Path) -> dict[str, str]:
    """A calibrated copy of the embedded store (its westbound first 10 minutes), and
    scenario B with ``--behaviour calibrated`` on it."""
    from twin.data.embedded import default_store

    store = work / "calibrated_store"
    shutil.copytree(default_store().path, store)
    for stale in ("calibration.json", "calibration_fits.parquet"):
        (store / stale).unlink(missing_ok=True)
    twin(
        f"calibrate {store} --road westbound --from 2022-11-30T06:39:30-06:00 "
        "--until 2022-11-30T06:49:30-06:00 --quiet"
    )
    calibration = json.loads((store / "calibration.json").read_text())
    calibration.pop("created", None)
    folder = work / "run_B_calibrated"
    twin(
        f"run --scenario B --data {store} --seed 3 --duration 10 --behaviour calibrated "
        f"--quiet --out {folder}"
    )
    return {
        "calibration": hashlib.sha256(
            json.dumps(
                _without_keys(calibration, {"created", "elapsed_s", "store"}), sort_keys=True
            ).encode()
        ).hexdigest(),
        "calibration_fits": table_digest(store / "calibration_fits.parquet"),
        "run_B_calibrated": table_digest(folder / "trajectories.parquet"),
        "run_B_calibrated_metrics": metrics_digest(folder / "metrics.json"),
    }


def metrics_digest(path: Path) -> str:
    """SHA-256 of a run's ``metrics.json`` without its wall-clock ``timing``."""
    figures = json.loads(path.read_text())
    figures.pop("timing")
    return hashlib.sha256(json.dumps(figures, sort_keys=True).encode()).hexdigest()


def _without_keys(value, keys):
    if isinstance(value, dict):
        return {k: _without_keys(v, keys) for k, v in value.items() if k not in keys}
    if isinstance(value, list):
        return [_without_keys(v, keys) for v in value]
    return value


def eval_digest(work: Path) -> dict[str, str]:
    folder = work / "eval"
    twin(f"eval --episodes 4 --duration 20 --seed 1 --workers 1 --quiet --out {folder}")
    return {"eval_episodes": table_digest(folder / "episodes.parquet", drop=TIMING_COLUMNS)}


def dataset_digest(work: Path) -> dict[str, str]:
    folder = work / "dataset"
    twin(f"dataset --episodes 2 --frames-per-episode 3 --seed 5 --workers 1 --quiet --out {folder}")
    labels = [(folder, p) for p in folder.rglob("*.txt") if "label" in str(p.relative_to(folder))]
    coco = [
        (folder, p)
        for p in folder.rglob("*.json")
        if "coco" in p.name.lower() or "annotations" in str(p.relative_to(folder))
    ]
    if not labels or not coco:
        raise RuntimeError(f"no KITTI labels or COCO file under {folder}")
    return {"dataset_kitti_labels": files_digest(labels), "dataset_coco": files_digest(coco)}


def env_digest() -> dict[str, str]:
    """The env's observations and rewards over 200 seeded random actions."""
    import gymnasium as gym

    import twin.env

    env = gym.make(twin.env.ENV_ID)
    obs, _ = env.reset(seed=11)
    env.action_space.seed(11)
    digest = hashlib.sha256(np.asarray(obs, np.float32).tobytes())
    for _ in range(200):
        obs, reward, terminated, truncated, _ = env.step(env.action_space.sample())
        digest.update(np.asarray(obs, np.float32).tobytes())
        digest.update(np.float64(reward).tobytes())
        if terminated or truncated:
            digest.update(b"reset")
            obs, _ = env.reset()
            digest.update(np.asarray(obs, np.float32).tobytes())
    env.close()
    return {"env_200_steps": digest.hexdigest()}


def synth_digest(work: Path) -> dict[str, str]:
    path = work / "b.json"
    twin(f"data synth --preset B --minutes 2 --quiet --out {path}")
    return {"synth_B_2min": hashlib.sha256(path.read_bytes()).hexdigest()}


def fingerprint() -> dict[str, str]:
    """What the digests depend on besides the code: the libraries that compute and the
    CPU features numpy dispatches its loops on and Numba compiles the kernels for (a
    different machine may round its last bits differently, and a new library release
    may too)."""
    import platform
    from importlib.metadata import version

    from numpy._core._multiarray_umath import __cpu_features__

    libraries = (
        "numpy",
        "numba",  # compiles the traffic core's kernels
        "scipy",
        "pandas",
        "pyarrow",
        "pybullet",
        "trimesh",
        "opencv-python-headless",
        "gymnasium",
    )
    return {
        "python": platform.python_version(),
        "machine": platform.machine(),
        **{name: version(name) for name in libraries},
        "cpu": ",".join(sorted(k for k, on in __cpu_features__.items() if on)),
    }


def all_digests() -> dict[str, str]:
    with tempfile.TemporaryDirectory(prefix="i24-golden-") as tmp:
        work = Path(tmp)
        out = {}
        out.update(synth_digest(work))
        out.update(run_digests(work))
        out.update(calibrated_run_digest(work))
        out.update(eval_digest(work))
        out.update(dataset_digest(work))
        out.update(env_digest())
        return out


if __name__ == "__main__":
    digests = all_digests()
    json.dump(
        {"fingerprint": fingerprint(), "digests": digests}, sys.stdout, indent=1, sort_keys=True
    )
    print()
