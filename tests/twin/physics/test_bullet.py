"""pybullet's native output: the banner and the EGL driver's lines stay out of the terminal,
anything else it says is passed on."""

import ctypes
import os
import subprocess
import sys

from twin.physics.bullet import CHATTER, captured_native_output, filtered_native_output
from twin.physics.render import gl_renderer_of


def test_native_writes_are_captured_and_the_descriptors_restored(capfd):
    libc = ctypes.CDLL(None)
    with captured_native_output() as captured:
        os.write(1, b"to fd 1\n")
        os.write(2, b"to fd 2\n")
        libc.printf(b"buffered by C stdio\n")  # a file, not a terminal: fully buffered
    os.write(1, b"after\n")
    assert captured.text.splitlines() == ["to fd 1", "to fd 2", "buffered by C stdio"]
    assert capfd.readouterr().out == "after\n"


def test_chatter_is_dropped_and_anything_else_passed_on(capfd):
    with filtered_native_output() as captured:
        os.write(1, b"pybullet build time: Jan 29 2025 23:17:20\nven = Mesa/X.org\n")
        os.write(2, b"b3Warning: something the twin has not seen\n")
    out, err = capfd.readouterr()
    assert out == ""
    assert err == "pybullet: b3Warning: something the twin has not seen\n"
    assert "ven = Mesa/X.org" in captured.text


def test_output_is_restored_when_the_block_raises(capfd):
    try:
        with filtered_native_output():
            os.write(2, b"said before failing\n")
            raise RuntimeError("boom")
    except RuntimeError:
        pass
    os.write(2, b"after\n")
    assert capfd.readouterr().err == "pybullet: said before failing\nafter\n"


def test_importing_the_physics_prints_nothing():
    """A fresh interpreter: pybullet's ``pybullet build time`` banner is not shown."""
    result = subprocess.run(
        [sys.executable, "-c", "import twin.physics.render, sensors.map_preview"],
        capture_output=True,
        text=True,
        check=True,
    )
    assert result.stdout == "" and result.stderr == ""


def test_the_egl_plugins_lines_are_known_chatter():
    lines = [  # as pybullet 3.2.7's EGL plugin prints them on Mesa
        "EGL device choice: -1 of 1.",
        "Loaded EGL 1.5 after reload.",
        "GL_VENDOR=Mesa/X.org",
        "GL_RENDERER=llvmpipe (LLVM 15.0.6, 256 bits)",
        "GL_VERSION=4.5 (Core Profile) Mesa 22.3.6",
        "GL_SHADING_LANGUAGE_VERSION=4.50",
        "Version = 4.5 (Core Profile) Mesa 22.3.6",
        "Vendor = Mesa/X.org",
        "Renderer = llvmpipe (LLVM 15.0.6, 256 bits)",
        "ven = Mesa/X.org",
        "Destroy EGL OpenGL window.",
    ]
    assert all(line.startswith(CHATTER) for line in lines)
    assert gl_renderer_of("\n".join(lines)) == "llvmpipe (LLVM 15.0.6, 256 bits)"
    assert gl_renderer_of("nothing of the kind") == ""
