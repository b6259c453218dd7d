"""The project's Modelica library ``MCL`` (package data): interfaces, example systems.

It is on the library path of every compile by default (:func:`mcl.compile.library.library_path`), so
models and exported libraries that use ``MCL.*`` work from any directory after ``pip install``.
"""
from pathlib import Path

#: The ``MCL`` package directory.
MCL_LIBRARY = Path(__file__).resolve().parent / "MCL"
