"""Shared setup of the Python tests: this folder on sys.path, and skips. The package comes from
PYTHONPATH: the build tree's python/ folder, where the build assembles it with its generated stubs
(ctest sets it).

Run a test file with /usr/bin/python3 (Debian's numpy, VTK, meshio); exit code 77 means every
test was skipped (a dependency is missing), which ctest reports as skipped.
"""

import os
import shutil
import sys
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, HERE)

SKIPPED = 77


def have_module(name):
    try:
        __import__(name)
        return True
    except ImportError:
        return False


def can_render():
    """None when VTK can draw here (a DISPLAY or Xvfb), else the reason it cannot."""
    if not have_module("vtkmodules.vtkRenderingOpenGL2"):
        return "VTK's Python bindings are not installed (Debian: python3-vtk9)"
    if not os.environ.get("DISPLAY") and shutil.which("Xvfb") is None:
        return "no DISPLAY and no Xvfb (Debian: xvfb)"
    return None


def main():
    """unittest.main, but exit 77 when tests ran and all of them were skipped."""
    program = unittest.main(exit=False)
    result = program.result
    if not result.wasSuccessful():
        sys.exit(1)
    if result.testsRun and len(result.skipped) == result.testsRun:
        for _, reason in result.skipped[:1]:
            print("all tests skipped: %s" % reason)
        sys.exit(SKIPPED)
    sys.exit(0)
