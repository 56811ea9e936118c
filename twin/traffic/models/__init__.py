"""Car-following models by name (:mod:`twin.traffic.models.base` for the interface).

A new model is one module beside these (its parameter dataclass, its vectorised
acceleration and a :class:`~twin.traffic.models.base.CarFollowingModel`) plus one
line in :data:`MODELS`; ``docs/architecture.md`` gives the steps.
"""

from twin.traffic.models.base import CarFollowingModel
from twin.traffic.models.gipps import GIPPS
from twin.traffic.models.idm import IDM, TEXTBOOK_IDM

__all__ = [
    "AUTO",
    "GIPPS",
    "IDM",
    "MODELS",
    "TEXTBOOK_IDM",
    "UNCALIBRATED",
    "CarFollowingModel",
    "car_following_model",
]

#: Every model, by the name configurations and the command line use.
MODELS: dict[str, CarFollowingModel] = {m.name: m for m in (IDM, TEXTBOOK_IDM, GIPPS)}
#: Not a model: ``traffic.car_following``'s default, the model the store's calibration
#: fitted (``idm`` where there is none; :func:`twin.cosim.behaviour.car_following_of`),
#: and ``twin calibrate --model``'s, the model that replays the recording best
#: (:mod:`twin.calibration.model_choice`).
AUTO = "auto"
#: What :data:`AUTO` stands for where there is no calibration to follow (the paper's
#: drivers, a store without one, a manager without a store).
UNCALIBRATED = IDM.name


def car_following_model(name: str) -> CarFollowingModel:
    """The registered model ``name``.

    Raises:
        ValueError: naming the unknown model and the known ones.
    """
    try:
        return MODELS[name]
    except KeyError:
        raise ValueError(
            f"unknown car-following model {name!r}: choose one of {', '.join(MODELS)}"
        ) from None
