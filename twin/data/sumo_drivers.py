"""SUMO's drivers of a day made by :func:`twin.data.sumo_day.sumo_day`: the car-following
and lane-changing models SUMO offers here and :class:`SumoDrivers`, the vType attributes
every vehicle type of a day is given in place of SUMO's defaults (checked against their
ranges). Apart from :mod:`twin.data.sumo_day`, which drives SUMO, so that a family's
draw (:mod:`twin.data.sumo_family`) can name drivers without the run.
"""

from dataclasses import dataclass

from twin.core import i24
from twin.core.errors import TwinError

STEP = 0.1  # [s] SUMO's step
#: SUMO's car-following models a day may be driven by (its ``carFollowModel`` names)
CAR_FOLLOWING = ("Krauss", "IDM", "EIDM")
#: ... and its lane-changing models (``laneChangeModel``); SL2015 runs on the sublane model
LANE_CHANGING = ("LC2013", "SL2015")
#: the car-following models that dawdle by ``sigma`` (SUMO's IDM does not; its EIDM has
#: estimation and driving errors of its own, left at SUMO's defaults)
DAWDLING = ("Krauss",)
#: SUMO classes whose acceleration and braking stay SUMO's class defaults under
#: :class:`SumoDrivers` (a lorry is not a car whatever the day's drivers)
HEAVY_SUMO_CLASSES = ("trailer", "truck")


class SumoDayError(TwinError):
    """SUMO failed, or the preset cannot be driven in SUMO."""


@dataclass(frozen=True)
class SumoDrivers:
    """SUMO's drivers for every vehicle type of a day, in place of SUMO's defaults.

    Attributes:
        car_following: SUMO's ``carFollowModel``: ``"Krauss"``, ``"IDM"`` or ``"EIDM"``.
        lane_changing: SUMO's ``laneChangeModel``: ``"LC2013"`` or ``"SL2015"`` (on the
            sublane model, at ``lateral_resolution``; SUMO's lane changes then take as
            long as its lateral speed needs, not ``lane_change_duration``).
        tau: [s] desired time headway (``tau``).
        sigma: [-] dawdling, 0 to 1 (``sigma``), for Krauss; None for IDM and EIDM
            (EIDM's own estimation and driving errors keep SUMO's defaults).
        min_gap: [m] standstill gap (``minGap``).
        accel, decel: [m/s^2] maximum acceleration and comfortable braking of the light
            vehicles (``accel``, ``decel``); heavy vehicles (SUMO's ``truck`` and
            ``trailer``) keep SUMO's defaults for their class.
        speed_dev: [-] standard deviation of the drivers' speed factor (``speedDev``):
            each class keeps its mean desired speed, the spread is this, clipped at 2 sd.
        lc_strategic, lc_cooperative, lc_speed_gain, lc_keep_right, lc_assertive: [-]
            the lane-changing model's eagerness for strategic, cooperative, speed-gain
            and keep-right changes and its willingness to take smaller gaps
            (``lcStrategic``, ``lcCooperative`` 0 to 1, ``lcSpeedGain``,
            ``lcKeepRight``, ``lcAssertive`` > 0).
        action_step: [s] how often a driver decides (``actionStepLength``), a multiple
            of SUMO's 0.1 s step: its reaction time, which spares SUMO most of its
            work (SL2015's above all).
        lateral_resolution: [m] the sublane model's resolution (SUMO's
            ``--lateral-resolution``), used with SL2015 only.

    Raises:
        SumoDayError: a model SUMO does not offer here or a value out of its range.
    """

    car_following: str
    lane_changing: str
    tau: float
    sigma: float | None
    min_gap: float
    accel: float
    decel: float
    speed_dev: float
    lc_strategic: float
    lc_cooperative: float
    lc_speed_gain: float
    lc_keep_right: float
    lc_assertive: float
    action_step: float = STEP
    lateral_resolution: float = 0.8

    def __post_init__(self):
        if self.car_following not in CAR_FOLLOWING:
            raise SumoDayError(
                f"car_following {self.car_following!r}: expected one of {', '.join(CAR_FOLLOWING)}"
            )
        if self.lane_changing not in LANE_CHANGING:
            raise SumoDayError(
                f"lane_changing {self.lane_changing!r}: expected one of {', '.join(LANE_CHANGING)}"
            )
        if (self.sigma is None) == (self.car_following in DAWDLING):
            raise SumoDayError(
                f"sigma {self.sigma!r}: {self.car_following} needs one (0 to 1)"
                if self.sigma is None
                else f"sigma {self.sigma!r}: {self.car_following} does not dawdle; give None"
            )
        checks = {
            "tau": self.tau > 0,
            "sigma": self.sigma is None or 0 <= self.sigma <= 1,
            "min_gap": self.min_gap >= 0,
            "accel": self.accel > 0,
            "decel": self.decel > 0,
            "speed_dev": 0 <= self.speed_dev < 0.5,
            "lc_strategic": self.lc_strategic >= 0,
            "lc_cooperative": 0 <= self.lc_cooperative <= 1,
            "lc_speed_gain": self.lc_speed_gain >= 0,
            "lc_keep_right": self.lc_keep_right >= 0,
            "lc_assertive": self.lc_assertive > 0,
            "action_step": self.action_step >= STEP
            and abs(self.action_step / STEP - round(self.action_step / STEP)) < 1e-6,
            "lateral_resolution": 0 < self.lateral_resolution <= i24.LANE_WIDTH,
        }
        for name, ok in checks.items():
            if not ok:
                raise SumoDayError(
                    f"SumoDrivers.{name} is out of its range: {getattr(self, name)!r}"
                )

    @property
    def sublane(self) -> bool:
        """Whether SUMO runs its sublane model (SL2015's lane changes need it)."""
        return self.lane_changing == "SL2015"

    def attributes(self, sumo_class: str) -> dict[str, str]:
        """The vType attributes of a type of SUMO class ``sumo_class``."""
        out = {"carFollowModel": self.car_following, "tau": f"{self.tau:.3f}",
               "minGap": f"{self.min_gap:.3f}",
               "actionStepLength": f"{self.action_step:.1f}"}  # fmt: skip
        if self.sigma is not None:
            out["sigma"] = f"{self.sigma:.3f}"
        if sumo_class not in HEAVY_SUMO_CLASSES:
            out |= {"accel": f"{self.accel:.3f}", "decel": f"{self.decel:.3f}"}
        out |= {
            "laneChangeModel": self.lane_changing,
            "lcStrategic": f"{self.lc_strategic:.3f}",
            "lcCooperative": f"{self.lc_cooperative:.3f}",
            "lcSpeedGain": f"{self.lc_speed_gain:.3f}",
            "lcKeepRight": f"{self.lc_keep_right:.3f}",
            "lcAssertive": f"{self.lc_assertive:.3f}",
        }
        return out
