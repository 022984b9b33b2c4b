"""Only the compiled kernels need setup.py: cffi builds ``dolfinx_dem.kernels._kernels`` from the C
files of ``dolfinx_dem/kernels/`` at install (``make setup``); everything else is in pyproject.toml."""

from setuptools import setup

setup(cffi_modules=["dolfinx_dem/kernels/_build.py:ffibuilder"])
