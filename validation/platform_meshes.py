"""Write the meshes of the built-in scenes that gmsh makes (discs, balls) to XDMF files, with
their cell and facet tags, so that two platforms with different gmsh versions can run the same
discrete problem (``--set 'mesh={type="file", path="DIR/SCENE.xdmf"}'``; docs/platforms.md).

    .venv/bin/python validation/platform_meshes.py DIR
"""

import argparse
import pathlib

import dolfinx.io
from mpi4py import MPI

from dolfinx_dem import _compat, model, scenes

GMSH_SCENES = ("ball-drop", "billiard", "cradle", "hertz", "hertz3d", "indentation", "two-balls", "two-disks")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=pathlib.Path)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for name in GMSH_SCENES:
        mesh, cell_tags, facet_tags, _ = model.create_mesh(MPI.COMM_WORLD, scenes.load(name)["mesh"])
        with dolfinx.io.XDMFFile(MPI.COMM_WORLD, str(args.out / f"{name}.xdmf"), "w") as xdmf:
            mesh.name = "mesh"
            xdmf.write_mesh(mesh)
            for tags, tag_name in ((cell_tags, "cell_tags"), (facet_tags, "facet_tags")):
                if tags is not None:
                    tags.name = tag_name
                    _compat.write_meshtags(xdmf, tags, mesh)
        print(name, mesh.topology.index_map(mesh.topology.dim).size_global, "cells")


if __name__ == "__main__":
    main()
