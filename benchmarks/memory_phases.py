"""Resident memory at the phase boundaries of bench_parallel.py's 2D scaling scene (issue 11).

Prints, per process, VmRSS and VmHWM (the peak so far) from /proc/self/status after the
baseline (Python, DOLFINx, PETSc), the mesh, the set-up (``DEMDiscretisation``), the stable
time step, MEMM's construction, its initialisation and 5 steps: the phase whose VmHWM first
reaches the final peak holds it. No sampling thread (a thread changes what it measures).

    mpirun -n P .venv/bin/python benchmarks/memory_phases.py [cells]      (default 1,000,000)
"""

from __future__ import annotations

import sys


def status() -> dict[str, float]:
    """VmRSS and VmHWM of this process (MB)."""
    out = {}
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(("VmRSS", "VmHWM")):
                key, value = line.split(":")
                out[key] = int(value.split()[0]) / 1024.0
    return out


def main(cells: int) -> None:
    from mpi4py import MPI

    from dolfinx_dem import meshes
    from dolfinx_dem.conditions import DirichletBC
    from dolfinx_dem.discretisation import DEMDiscretisation
    from dolfinx_dem.material import ElasticMaterial
    from dolfinx_dem.memm import MEMM

    comm = MPI.COMM_WORLD
    log = []

    def mark(name: str):
        s = status()
        log.append(f"{name:10s} rss {s['VmRSS']:7.0f} MB  peak so far {s['VmHWM']:7.0f} MB")

    mark("baseline")
    n = max(1, round((cells / 4) ** 0.5))
    mesh, _, tags = meshes.create_rectangle(comm, [0, 0], [1, 1], [n, n], "crossed")
    mark("mesh")
    dem = DEMDiscretisation(mesh, ElasticMaterial(E=1.0e4, nu=0.3, rho=1.0), "A",
                            [DirichletBC(tags.find(meshes.XMIN), [0.0, 0.0])], body_force=[0.0, -1.0])
    mark("set-up")
    dt = 0.5 * dem.stable_time_step()
    mark("stable")
    memm = MEMM(dem, dt)
    mark("memm")
    memm.initialise(dem.create_vector(), dem.create_vector())
    mark("initialise")
    for _ in range(5):
        memm.step()
    mark("steps")
    logs = comm.gather("\n".join(log), root=0)
    if comm.rank == 0:
        for rank, text in enumerate(logs):
            print(f"rank {rank} of {comm.size}, {dem.geometry.num_cells_global:,} cells\n{text}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 1_000_000)
