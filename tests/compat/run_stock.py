"""Run a compat script with stock roslibpy: ``python run_stock.py script.py``.

It maps ``roslibpy_lite.compat`` to the real ``roslibpy`` before running the
script, so the very same file shows it is roslibpy code but for its import.
"""

import runpy
import sys

import roslibpy

import roslibpy_lite

sys.modules["roslibpy_lite.compat"] = roslibpy
roslibpy_lite.compat = roslibpy  # type: ignore[attr-defined]
runpy.run_path(sys.argv[1], run_name="__main__")
