"""Calibrated stores with one westbound section of ``calibration.json`` edited, and the
traffic settings a behaviour derives from them: for the tests of the calibrated
behaviours' settings (yielding, passing on the right)."""

import json
import shutil
from dataclasses import replace

from twin.cosim.config import CosimConfig
from twin.cosim.core.batch import Shared
from twin.data.store import TrajectoryStore


def with_section(source: TrajectoryStore, folder, name: str, section) -> TrajectoryStore:
    """A copy of ``source`` in ``folder`` whose westbound ``name`` section is ``section``;
    ``None`` deletes it (a calibration made before the section existed)."""
    shutil.copytree(source.path, folder)
    path = folder / "calibration.json"
    doc = json.loads(path.read_text())
    if section is None:
        del doc["roads"]["westbound"][name]
    else:
        doc["roads"]["westbound"][name] = section
    path.write_text(json.dumps(doc))
    return TrajectoryStore(folder)


def settings(store, built_map, behaviour="calibrated", **traffic):
    """The traffic settings a kinematic run of ``behaviour`` on ``store`` drives, with the
    ``traffic`` config fields given."""
    config = CosimConfig(world="kinematic", t_max=10.0, behaviour=behaviour)
    config = replace(config, traffic=replace(config.traffic, **traffic))
    return Shared.make(store, built_map, config).traffic_settings
