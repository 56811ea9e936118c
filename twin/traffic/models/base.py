"""The car-following model interface: a parameter dataclass and one vectorised function.

A model is a :class:`CarFollowingModel`: its parameters (a frozen dataclass holding
one (n,) float64 array or scalar per parameter, with bounds and a starting value for
calibration), its acceleration ``accel(v, v_lead, gap, params) -> a``, and how the
class table's drivers translate into its parameters. The traffic manager, the
synthesiser and the calibration take any model through this interface and nothing
else; :mod:`twin.traffic.models` registers the models by name.

Drivers are drawn per vehicle class as *traits* (desired speed, time headway, minimum
gap, maximum acceleration, comfortable deceleration, acceleration exponent:
:class:`~twin.traffic.drivers.DriverDistribution` reading ``assets/vehicle_classes.csv``),
and each model says what its parameters are for a driver with those traits
(``from_traits``): the identity for IDM, Gipps' reaction time and braking from the
time headway and the comfortable deceleration.

Every model's parameters include ``desired_speed`` [m/s] (the cosimulation sets it;
it is fitted, since the calibration weighs it against the free-flow speeds) and
``max_accel`` [m/s^2] (the traffic manager's acceleration limit). Bounds are positive:
fits move in the logarithm of a parameter.
"""

from collections.abc import Callable
from dataclasses import dataclass, fields
from functools import cache

import numpy as np

#: What every model's parameters hold, because the traffic manager sets or reads them.
REQUIRED = ("desired_speed", "max_accel")


@dataclass(frozen=True)
class Parameter:
    """One parameter of a model.

    Attributes:
        name: its field in the model's parameter dataclass.
        unit: e.g. ``m/s``.
        symbol: its letter in the model's equations (``T``, ``s0``), for people.
        bounds: (low, high), both > 0: the calibration's box (wide enough for every
            driver of the literature's I-24, NGSIM and highD fits, narrow enough to
            reject nonsense).
        start: where a calibration starts: a typical passenger-car driver.
        fitted: calibrated from following data; a parameter that is not keeps the
            value ``start`` (IDM's exponent).
    """

    name: str
    unit: str
    symbol: str
    bounds: tuple[float, float]
    start: float
    fitted: bool = True

    def __post_init__(self):
        low, high = self.bounds
        if not 0 < low < high or not low <= self.start <= high:
            raise ValueError(f"parameter {self.name}: need 0 < low <= start <= high")


@dataclass(frozen=True)
class CarFollowingModel:
    """A car-following model (see the module doc).

    Attributes:
        name: registry name (``--set traffic.car_following=NAME``,
            ``twin calibrate --model NAME``).
        reference: where the model is defined.
        params: the parameter dataclass; its fields are ``parameters``' names in
            order, each (n,) float64 or a scalar.
        parameters: the parameters, in the dataclass's field order.
        accel: ``accel(v, v_lead, gap, params) -> (n,) [m/s^2]`` of followers at
            speeds ``v`` (n,) [m/s] behind leaders at ``v_lead`` (n,) [m/s] with a
            bumper-to-bumper ``gap`` (n,) [m] (``inf``: a free road, ``v_lead``
            ignored); unclipped. A desired speed of 0 brakes to a stop and holds it.
        from_traits: ``from_traits(traits) -> params``: the model's parameters for
            drivers with these traits (:class:`~twin.traffic.drivers.DriverTraits` of
            (n,) arrays or scalars).
    """

    name: str
    reference: str
    params: type
    parameters: tuple[Parameter, ...]
    accel: Callable[..., np.ndarray]
    from_traits: Callable[..., object]

    def __post_init__(self):
        names = tuple(f.name for f in fields(self.params))
        if names != self.names:
            raise ValueError(f"{self.name}: parameters {self.names} differ from {names}")
        missing = [name for name in REQUIRED if name not in names]
        if missing:
            raise ValueError(f"{self.name}: every model needs the parameters {missing}")
        if "desired_speed" not in (p.name for p in self.fitted):
            raise ValueError(f"{self.name}: desired_speed must be a fitted parameter")

    @property
    def names(self) -> tuple[str, ...]:
        """The parameters' names, in order."""
        return tuple(p.name for p in self.parameters)

    @property
    def fitted(self) -> tuple[Parameter, ...]:
        """The parameters a calibration fits, in order."""
        return tuple(p for p in self.parameters if p.fitted)

    def make(self, **values) -> object:
        """Parameters from named values, (n,) arrays or scalars; the unfitted ones that
        are not given take their ``start``.

        Raises:
            ValueError: an unknown or missing name.
        """
        unknown = sorted(set(values) - set(self.names))
        if unknown:
            raise ValueError(f"{self.name} has no parameters {unknown}; it has {self.names}")
        fixed = {p.name: p.start for p in self.parameters if not p.fitted}
        missing = [name for name in self.names if name not in values and name not in fixed]
        if missing:
            raise ValueError(f"{self.name}: no value for {missing}")
        return self.params(**{**fixed, **values})

    def from_fitted(self, matrix: np.ndarray) -> object:
        """Parameters from a (n, k) matrix of the fitted parameters' values, in the
        order of :attr:`fitted`."""
        matrix = np.asarray(matrix, dtype=np.float64)
        return self.make(**{p.name: matrix[:, j] for j, p in enumerate(self.fitted)})


def take(params, index) -> object:
    """The parameters of the vehicles at ``index`` (scalars are kept as they are; the
    parameters are numpy arrays or scalars)."""
    return type(params)(
        *(
            value[index] if isinstance(value, np.ndarray) and value.ndim else value
            for value in (getattr(params, name) for name in _names(type(params)))
        )
    )


def concatenate(params, extra) -> object:
    """``params`` (n,) followed by ``extra`` (k,), both of one model, field by field
    (scalars are repeated to their side's length)."""

    def column(p, name):
        value = getattr(p, name)
        if isinstance(value, np.ndarray) and value.ndim:
            return value
        return np.full(np.shape(p.desired_speed), value)

    return type(params)(
        *(
            np.concatenate([column(params, name), column(extra, name)])
            for name in _names(type(params))
        )
    )


@cache
def _names(params: type) -> tuple[str, ...]:
    """The fields of a parameter dataclass (the step asks for them often)."""
    return tuple(f.name for f in fields(params))
