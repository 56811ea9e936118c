"""The compiled kernels' common ground: how they are compiled, where their compiled code
is cached, and the counter-based random numbers they draw.

Every kernel of the batched core is a plain function over scalars and numpy arrays,
compiled by Numba with :func:`kernel`:

* ``cache=True``: the machine code is kept beside the source (``__pycache__``), or
  under ``$NUMBA_CACHE_DIR``, or, where the package folder is read-only, under the
  system's temporary folder, so that a process after the first
  loads it in a fraction of a second instead of compiling;
* ``error_model="numpy"``: a float division by zero gives ``inf`` or ``nan`` as numpy
  does (the twin's numpy code relied on it), not a ZeroDivisionError;
* no ``fastmath``: results are bit for bit those of IEEE arithmetic, the same in any
  batch and on any machine with the same build.

Random draws inside kernels come from :func:`uniform` and :func:`normal`, a hash of
counters (the run's seed, a stream, a vehicle's key, an event number): the same draw
for the same counters whatever the batch, the slot or the order of events, so an
episode is the same alone or in a batch of any size. ``NUMBA_BOUNDSCHECK=1`` makes
every array access checked (the tests run the kernels so once, with a cache of their
own).
"""

import math
import os
import tempfile

import numba
import numpy as np
from numba.core import types
from numba.experimental import structref

if not os.environ.get("NUMBA_CACHE_DIR") and not os.access(os.path.dirname(__file__), os.W_OK):
    numba.config.CACHE_DIR = os.path.join(tempfile.gettempdir(), "i24-twin-numba-cache")


INLINE_IR = os.environ.get("TWIN_INLINE_IR") == "1"


def kernel(function=None, *, inline: bool = False):
    """Compile ``function`` as a kernel of the core (see the module doc); with
    ``inline=True`` it is inlined where it is called (small scalar helpers)."""
    options = {"cache": True, "error_model": "numpy", "nogil": True}
    if inline and INLINE_IR:
        options["inline"] = "always"
    if function is None:
        return numba.njit(**options)
    return numba.njit(**options)(function)


_M1 = np.uint64(0x9E3779B97F4A7C15)
_M2 = np.uint64(0xBF58476D1CE4E5B9)
_M3 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_ONE = np.uint64(1)
_TO_UNIT = 1.0 / 9007199254740992.0  # 2^-53


@kernel(inline=True)
def _mix(z):
    z = (z ^ (z >> _S30)) * _M2
    z = (z ^ (z >> _S27)) * _M3
    return z ^ (z >> _S31)


@kernel(inline=True)
def uniform(seed, stream, key, event):
    """U[0, 1) from four non-negative integer counters (SplitMix64 finalisers chained):
    the run's ``seed``, a ``stream`` per kind of draw, the drawing vehicle's ``key``
    and an ``event`` number (a count of its draws, a bin, ...)."""
    z = _mix(np.uint64(seed) + _M1 * (np.uint64(stream) + _ONE))
    z = _mix(z + _M1 * (np.uint64(key) + _ONE))
    z = _mix(z + _M1 * (np.uint64(event) + _ONE))
    return np.float64(z >> _S11) * _TO_UNIT


@kernel(inline=True)
def normal(seed, stream, key, event):
    """A standard normal draw: Box-Muller on the :func:`uniform` draws of events
    ``2 event`` and ``2 event + 1`` (so that a normal's events never meet another's)."""
    u1 = uniform(seed, stream, key, 2 * event)
    u2 = uniform(seed, stream, key, 2 * event + 1)
    return math.sqrt(-2.0 * math.log(1.0 - u1)) * math.cos(2.0 * math.pi * u2)


@kernel
def uniforms(seed, stream, keys, event):
    """(n,) :func:`uniform` of each of ``keys`` (n,) int64 at one ``event`` (for Python)."""
    out = np.empty(keys.size)
    for i in range(keys.size):
        out[i] = uniform(seed, stream, keys[i], event)
    return out


class StructType(types.StructRef):
    """A struct of the core's state groups (:func:`packing`): one pointer to pass, so
    that a kernel's call and its compilation do not grow with the number of arrays."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


def packing(struct_type, group):
    """The implementation of a packer: a new ``struct_type`` holding the fields of the
    namedtuple type ``group`` (the same arrays). Use as an ``overload`` of a stub."""
    sty = struct_type([(name, typ) for name, typ in zip(group.fields, group.types, strict=True)])
    lines = ["def impl(group):", "    s = new(sty)"]
    lines += [f"    s.{name} = group.{name}" for name in group.fields]
    lines += ["    return s"]
    scope = {"new": structref.new, "sty": sty}
    exec("\n".join(lines), scope)
    return scope["impl"]
