"""The compiled kernels' common ground: how they are compiled, where their compiled code
is cached, and the counter-based random numbers they draw.

Every kernel of the batched core is a plain function over scalars and numpy arrays,
compiled by Numba with :func:`kernel`:

* ``cache=True``: the machine code is kept in a folder named by a digest of the
  kernels' sources (:func:`sources_digest`: every module that defines kernels and
  every twin module those import), under ``$NUMBA_CACHE_DIR``, else the twin's cache
  folder (``kernels/``), else, where that cannot be written, the system's temporary
  folder, so that a process after the first loads it in a fraction of a second
  instead of compiling. Numba checks only the time stamp of a kernel's own file, so a
  cache beside the sources kept a kernel compiled with an older version of a kernel
  it calls in another module, or of a constant it reads from one; a new digest is a
  new folder, compiled afresh;
* ``error_model="numpy"``: a float division by zero gives ``inf`` or ``nan`` as numpy
  does (the twin's numpy code relied on it), not a ZeroDivisionError;
* no ``fastmath``: results are bit for bit those of IEEE arithmetic, the same in any
  batch and on any machine with the same build;
* no reference counting (``nrt=False``) unless asked for: a kernel makes no arrays,
  and the arrays it reads live as long as the Python objects holding them, so
  counting them (an atomic increment and decrement per array read or passed on) was
  pure cost; kernels that make arrays or structs, or that Python calls with a packed
  struct (:func:`register_struct`), take ``nrt=True``.

Random draws inside kernels come from :func:`uniform` and :func:`normal`, a hash of
counters (the run's seed, a stream, a vehicle's key, an event number): the same draw
for the same counters whatever the batch, the slot or the order of events, so an
episode is the same alone or in a batch of any size. ``NUMBA_BOUNDSCHECK=1`` makes
every array access checked (the tests run the kernels so once, with a cache of their
own).
"""

import hashlib
import math
import os
import re
import tempfile
from pathlib import Path

import numba
import numpy as np
from numba.core import caching, cgutils, imputils, types
from numba.core.datamodel import default_manager, models
from numba.core.extending import (
    NativeValue,
    box,
    infer_getattr,
    lower_getattr_generic,
    lower_setattr_generic,
    unbox,
)
from numba.core.runtime.nrtdynmod import _meminfo_struct_type
from numba.core.typing.templates import AttributeTemplate
from numba.experimental import structref

PACKAGE = Path(__file__).resolve().parents[1]  # twin/
_DEFINES = re.compile(rb"@kernel|@overload|njit")
_IMPORTS = re.compile(
    rb"^\s*(?:from\s+(twin(?:\.\w+)*)\s+import\s+(\([^)]*\)|[\w, ]+)|import\s+(twin(?:\.\w+)*))",
    re.MULTILINE,
)


def kernel_sources(package: Path = PACKAGE) -> list[Path]:
    """The modules of ``package`` that define kernels, and every module of it that
    they import, directly or not, in path order."""

    def module(name: str) -> Path | None:
        parts = name.split(".")[1:]
        for path in (package.joinpath(*parts).with_suffix(".py"),
                     package.joinpath(*parts, "__init__.py")):  # fmt: skip
            if parts and path.is_file():
                return path
        return None

    todo = [p for p in package.rglob("*.py") if _DEFINES.search(p.read_bytes())]
    found = set(todo)
    while todo:
        text = todo.pop().read_bytes()
        for match in _IMPORTS.finditer(text):
            names = [(match.group(1) or match.group(3)).decode()]
            if match.group(1):  # from twin.a import b: b may be a module
                names += [f"{names[0]}.{n.strip()}" for n in re.split(r"[,()\s]+",
                          match.group(2).decode()) if n.strip()]  # fmt: skip
            for path in filter(None, map(module, names)):
                if path not in found:
                    found.add(path)
                    todo.append(path)
    return sorted(found)


def sources_digest(files: list[Path], package: Path = PACKAGE) -> str:
    """16 hex digits of the files' paths (relative to ``package``) and contents."""
    digest = hashlib.sha256()
    for path in files:
        digest.update(path.relative_to(package).as_posix().encode() + b"\0")
        digest.update(path.read_bytes() + b"\0")
    return digest.hexdigest()[:16]


def _cache_folder() -> str:
    """Where this version of the kernels keeps its compiled code (module doc)."""
    from twin.core.paths import cache_dir

    key = sources_digest(kernel_sources())
    for base in (os.environ.get("NUMBA_CACHE_DIR"), str(cache_dir() / "kernels")):
        if not base:
            continue
        folder = os.path.join(base, key)
        try:
            os.makedirs(folder, exist_ok=True)
        except OSError:
            continue
        if os.access(folder, os.W_OK):
            return folder
    return os.path.join(tempfile.gettempdir(), "i24-twin-kernels", key)


numba.config.CACHE_DIR = _cache_folder()


def _locked_save(save):
    """Numba's ``IndexDataCacheFile.save`` under a lock between processes on the index.

    Numba reads a function's index, picks the first free data file name for a new
    signature and writes the index back, with nothing between processes: two processes
    compiling two signatures of one kernel at once (test workers, the workers of an
    evaluation, the first run's second process) both picked ``NAME.1.nbc``, the second
    overwrote the first's machine code and the index kept one of them, so a later
    process could load one signature's code for the other. Under an ``flock`` on a file
    beside the index, the read, the choice and both writes are one step."""
    import fcntl

    def locked(self, key, data):
        with open(self._index_path + ".lock", "a") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            try:
                return save(self, key, data)
            finally:
                fcntl.flock(lock, fcntl.LOCK_UN)

    locked.__wrapped__ = save
    return locked


if not hasattr(caching.IndexDataCacheFile.save, "__wrapped__"):
    caching.IndexDataCacheFile.save = _locked_save(caching.IndexDataCacheFile.save)


INLINE_IR = os.environ.get("TWIN_INLINE_IR") == "1"


def kernel(function=None, *, inline: bool = False, nrt: bool = False):
    """Compile ``function`` as a kernel of the core (see the module doc); with
    ``inline=True`` it is inlined where it is called (small scalar helpers); with
    ``nrt=True`` it may make arrays or structs, or take a struct from Python (Numba's
    reference counting on: an entry point called with a packed struct releases it)."""
    options = {"cache": True, "error_model": "numpy", "nogil": True, "_nrt": nrt}
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


@kernel(nrt=True)
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


def register_struct(struct_type, proxy):
    """Register ``struct_type`` (a :class:`StructType`) and its Python ``proxy`` (a
    ``StructRefProxy``) for kernels, as ``numba.experimental.structref``'s ``register``
    and ``define_boxing`` do, except that reading a field works
    in a kernel compiled without reference counting (``nrt=False``, the default of
    :func:`kernel`): there it is a plain load of a borrowed reference. Counting every
    array a kernel reads from the struct (an atomic increment and decrement, in a call
    LLVM may not inline) cost more than the arithmetic of a vehicle's step; the
    struct's arrays stay alive because the Python side holds them for the whole call.
    Setting a field (only the packers do) still needs reference counting, and so does
    taking the struct from Python: a kernel without it would never release the
    reference its call takes, and the struct's arrays would live for ever, so such a
    call raises a TypeError that names the fix."""
    default_manager.register(struct_type, models.StructRefModel)
    meminfo_type = types.MemInfoPointer(types.voidptr)

    @infer_getattr
    class _Fields(AttributeTemplate):
        key = struct_type

        def generic_resolve(self, typ, attr):
            return typ.field_dict.get(attr)

    @lower_getattr_generic(struct_type)
    def _get(context, builder, typ, value, attr):
        payload = _payload(context, builder, typ, value)
        # a new reference where counting is on (as structref's own), else borrowed
        return imputils.impl_ret_borrowed(context, builder, typ.field_dict[attr],
                                          getattr(payload, attr))  # fmt: skip

    @lower_setattr_generic(struct_type)
    def _set(context, builder, signature, args, attr):
        typ, value_type = signature.args
        instance, value = args
        payload = _payload(context, builder, typ, instance)
        new = context.cast(builder, value, value_type, typ.field_dict[attr])
        old = getattr(payload, attr)
        context.nrt.incref(builder, value_type, new)
        context.nrt.decref(builder, value_type, old)  # last: the new may be the old
        setattr(payload, attr, new)

    @box(struct_type)
    def _box(typ, value, c):
        ref = cgutils.create_struct_proxy(typ)(c.context, c.builder, value=value)
        meminfo = c.box(meminfo_type, ref.meminfo)
        make = c.pyapi.unserialize(c.pyapi.serialize_object(proxy._numba_box_))
        typ_object = c.pyapi.unserialize(c.pyapi.serialize_object(typ))
        out = c.pyapi.call_function_objargs(make, [typ_object, meminfo])
        for held in (make, typ_object, meminfo):
            c.pyapi.decref(held)
        return out

    @unbox(struct_type)
    def _unbox(typ, obj, c):
        ref = cgutils.create_struct_proxy(typ)(c.context, c.builder)
        if not c.context.enable_nrt:  # every kernel has a wrapper; only a call fails
            c.pyapi.err_set_string(
                "PyExc_TypeError",
                f"a kernel taking a {typ.__class__.__name__} from Python needs reference "
                "counting: compile it with @kernel(nrt=True)",
            )
            return NativeValue(ref._getvalue(), is_error=cgutils.true_bit)
        held = c.pyapi.object_getattr_string(obj, "_meminfo")
        ref.meminfo = c.unbox(meminfo_type, held).value
        c.pyapi.decref(held)
        return NativeValue(ref._getvalue())

    return struct_type


def _payload(context, builder, typ, value):
    """The struct's payload behind its meminfo, read as Numba's own
    ``NRT_MemInfo_data_fast`` reads it (the data pointer, the meminfo's fourth field),
    without needing the runtime in the kernel."""
    ref = cgutils.create_struct_proxy(typ)(context, builder, value=value)
    meminfo = builder.bitcast(ref.meminfo, _meminfo_struct_type.as_pointer())
    data = builder.load(cgutils.gep(builder, meminfo, 0, 3))
    payload_type = typ.get_data_type()
    pointer = context.data_model_manager[payload_type].get_value_type().as_pointer()
    payload = cgutils.create_struct_proxy(payload_type)
    return payload(context, builder, ref=builder.bitcast(data, pointer))


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
