"""pybullet, imported and driven without the lines its C core prints.

pybullet's C core writes past Python's ``sys.stdout`` and ``sys.stderr``, straight to
the process's file descriptors: a ``pybullet build time: ...`` banner on stderr when
the module is imported (once per process, so once per dataset worker too), and the
GL driver's lines (``EGL device choice``, ``GL_VENDOR=...``, ``Destroy EGL OpenGL
window.``) when the EGL renderer plugin loads and unloads. Every module of the twin
imports pybullet from here, and the calls that print (the import, loading and
unloading the plugin, each EGL picture: ``ven = ...``) run under
:func:`filtered_native_output`: the lines known to be chatter are dropped, anything
else the C core says is passed on to stderr marked ``pybullet:``, and the caller may
read the text to turn what matters into its own message. Nothing else the process
prints is touched.
"""

import ctypes
import os
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass

STANDARD_FDS = (1, 2)  # stdout, stderr
CHATTER = (  # line starts, as pybullet 3.2.7 and its EGL plugin print them
    "pybullet build time:",
    "EGL device choice:",
    "Loaded EGL",
    "GL_VENDOR=",
    "GL_RENDERER=",
    "GL_VERSION=",
    "GL_SHADING_LANGUAGE_VERSION=",
    "Version = ",
    "Vendor = ",
    "Renderer = ",
    "ven = ",
    "Destroy EGL OpenGL window.",
)


@dataclass
class NativeOutput:
    """What native code wrote to stdout and stderr inside :func:`captured_native_output`
    (filled in when the block ends)."""

    text: str = ""


def _flush_c_streams() -> None:
    """Flush C stdio buffers, so native output lands where the descriptors point now."""
    with suppress(OSError, AttributeError):  # no C library to reach: nothing buffered there
        ctypes.CDLL(None).fflush(None)


def _flush_python_streams() -> None:
    for stream in (sys.stdout, sys.stderr):
        if stream is not None:
            stream.flush()


@contextmanager
def captured_native_output() -> Iterator[NativeOutput]:
    """Point file descriptors 1 and 2 at a temporary file for the block's duration.

    Python output written inside the block is captured too, so keep the block to the
    native call. Where a descriptor is closed, the block runs uncaptured.

    Yields:
        NativeOutput whose ``text`` holds what was written, once the block has ended.
    """
    captured = NativeOutput()
    _flush_python_streams()
    saved = []
    try:
        saved.extend(os.dup(fd) for fd in STANDARD_FDS)
    except OSError:
        for copy in saved:
            os.close(copy)
        yield captured
        return
    with tempfile.TemporaryFile() as sink:
        _flush_c_streams()
        try:
            for fd in STANDARD_FDS:
                os.dup2(sink.fileno(), fd)
            yield captured
        finally:
            _flush_python_streams()
            _flush_c_streams()
            for fd, copy in zip(STANDARD_FDS, saved, strict=True):
                os.dup2(copy, fd)
                os.close(copy)
            sink.seek(0)
            captured.text = sink.read().decode(errors="replace")


@contextmanager
def filtered_native_output() -> Iterator[NativeOutput]:
    """:func:`captured_native_output`, then every line that is not known chatter
    (:data:`CHATTER`) is written to stderr as ``pybullet: <line>``."""
    try:
        with captured_native_output() as captured:
            yield captured
    finally:
        said = [
            line
            for line in captured.text.splitlines()
            if line.strip() and not line.startswith(CHATTER)
        ]
        if said:
            print("\n".join(f"pybullet: {line}" for line in said), file=sys.stderr)


with filtered_native_output():
    import pybullet

__all__ = ["NativeOutput", "captured_native_output", "filtered_native_output", "pybullet"]
