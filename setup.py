"""Only the compiled kernels need setup.py: cffi builds ``dolfinx_dem._kernels`` from
``dolfinx_dem/kernels.c`` at install (``make setup``); everything else is in pyproject.toml."""

from setuptools import setup

setup(cffi_modules=["dolfinx_dem/_build_kernels.py:ffibuilder"])
