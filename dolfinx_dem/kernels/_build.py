"""cffi builder of ``dolfinx_dem.kernels._kernels`` from the C files of this folder; run at install
(setup.py's ``cffi_modules``), or by hand: ``python dolfinx_dem/kernels/_build.py`` (builds in place).

The declarations are those of ``dem_kernels.h`` (its preprocessor lines dropped: cffi reads
plain declarations); the module's source includes the same header, and each .c file is compiled
on its own and linked in. ``internal.h`` holds the static helpers the .c files share."""

import os
import pathlib

import cffi

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parent.parent  # the project: setup.py runs there, and ``compile`` below builds there
HEADER = HERE / "dem_kernels.h"
#: one file per concern: energy rows and MEMM, overlap geometry, flight and screen, events and
#: force integral, outputs, rigid obstacles
SOURCES = ["rows.c", "overlap.c", "flight.c", "integral.c", "outputs.c", "rigid.c"]


def declarations(header: str) -> str:
    """The header without its preprocessor lines (include guard, includes), for ``cdef``."""
    return "\n".join(line for line in header.splitlines() if not line.lstrip().startswith("#"))


def _relative(path: pathlib.Path) -> str:
    return os.path.relpath(path, ROOT)  # setuptools wants paths relative to the project


ffibuilder = cffi.FFI()
ffibuilder.cdef(declarations(HEADER.read_text()))
# -O3, no -march=native: the module must run on any x86-64 the package is installed for.
ffibuilder.set_source("dolfinx_dem.kernels._kernels", '#include "dem_kernels.h"',
                      sources=[_relative(HERE / name) for name in SOURCES], include_dirs=[_relative(HERE)],
                      depends=[_relative(HERE / name) for name in ("dem_kernels.h", "internal.h")],
                      extra_compile_args=["-O3", "-std=c99"])

if __name__ == "__main__":
    ffibuilder.compile(tmpdir=str(ROOT), verbose=True)
