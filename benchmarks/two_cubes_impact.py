"""A flat contact: two soft cubes (0.2 m, E = 100 Pa, nu = 0.2, rho = 100 kg/m^3, scheme B, gmsh
size H) 0.01 m apart along x meet head-on at +-0.3 m/s (the material and speed of `two-balls`);
the largest `penetration` over the run and the contact states at the given times
(``contact_states.save``, for ``contact_coverage.py``). OFFSET shifts the right cube in y and z;
``--no-sliding``: the diagnostic of ``contact_states.py``; ``--eta=ETA``: the stabilisation
parameter of eq. (13) (Pa, default E).

    .venv/bin/python benchmarks/two_cubes_impact.py H OFFSET OUT/tag 0.05 0.1 0.2 0.3 [--no-sliding] [--eta=1000]
"""

import pathlib
import sys

import numpy as np
from mpi4py import MPI

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests"))
from contact_states import save, without_sliding  # noqa: E402
from helpers import cell_vector, gmsh_mesh  # noqa: E402

from dolfinx_dem import _compat  # noqa: E402
from dolfinx_dem.discretisation import DEMDiscretisation  # noqa: E402
from dolfinx_dem.material import ElasticMaterial  # noqa: E402
from dolfinx_dem.memm import MEMM  # noqa: E402


def main():
    args = [a for a in sys.argv[1:] if a != "--no-sliding" and not a.startswith("--eta=")]
    if "--no-sliding" in sys.argv:
        without_sliding()
    eta = [float(a.split("=", 1)[1]) for a in sys.argv[1:] if a.startswith("--eta=")]
    h, offset, out, times = float(args[0]), float(args[1]), args[2], [float(t) for t in args[3:]]

    def build(gmsh):
        for k, corner in enumerate([(0.0, -0.1, -0.1), (0.21, -0.1 + offset, -0.1 + offset)]):
            box = gmsh.model.occ.addBox(*corner, 0.2, 0.2, 0.2)
            gmsh.model.occ.synchronize()
            gmsh.model.addPhysicalGroup(3, [box], k + 1)
        gmsh.option.setNumber("Mesh.MeshSizeMax", h)
        gmsh.model.mesh.generate(3)

    mesh = gmsh_mesh(MPI.COMM_SELF, build, gdim=3)
    dem = DEMDiscretisation(mesh, ElasticMaterial(E=100.0, nu=0.2, rho=100.0, eta=eta[-1] if eta else None), "B")
    dem.set_contact_boundary(_compat.locate_boundary_facets(mesh, lambda x: (x[0] > 0.19) & (x[0] < 0.22)))
    c = dem.pair_contact
    dt = 0.2 * dem.stable_time_step()
    stepper = MEMM(dem, dt)
    stepper.initialise(dem.create_vector(),
                       cell_vector(dem, lambda x: np.where((x[:, 0] < 0.205)[:, None], [0.3, 0, 0], [-0.3, 0, 0])))
    print(f"h = {h}: {dem.n_owned} cells, dt {dt:.3e} s", flush=True)
    worst, when = 0.0, 0.0
    for T in times:
        while stepper.t < T:
            stepper.step()
            p = c.penetration(c.patch_values(stepper.u))
            if p > worst:
                worst, when = p, stepper.t
        save(c, stepper.u, stepper.t, f"{out}_{stepper.t:.4f}.npz")
        print(f"  largest penetration so far {worst:.5f} m at {when:.4f} s", flush=True)


if __name__ == "__main__":
    main()
