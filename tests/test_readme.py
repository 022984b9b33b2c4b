"""The README's Python example, executed as it stands (public names only): the clamped plate
bends under its own weight onto the floor 0.02 below it (its static deflection is about 0.024)
and the pseudo-energy is conserved through the impacts (measured drift 4e-16)."""

import pathlib
import re

import pytest
from mpi4py import MPI

import dolfinx_dem

README = pathlib.Path(__file__).resolve().parents[1] / "README.md"


def _example() -> str:
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
    assert len(blocks) == 1, "the README holds one Python example"
    return blocks[0]


def test_the_readme_example_uses_public_names_only():
    code = _example()
    assert "import dolfinx_dem\n" in code
    assert "from dolfinx_dem" not in code and "_compat" not in code
    used = set(re.findall(r"dolfinx_dem\.(\w+)", code))
    assert used and used <= set(dolfinx_dem.__all__), used - set(dolfinx_dem.__all__)


@pytest.mark.mpi
def test_the_readme_example_runs_and_conserves_the_pseudo_energy():
    namespace = {}
    exec(compile(_example(), str(README), "exec"), namespace)  # noqa: S102 - the documentation's own code
    stepper, floor, problem = namespace["stepper"], namespace["floor"], namespace["problem"]
    assert namespace["drift"] < 1e-13
    # the plate reached the floor: contact events split the force integrals of some steps (a
    # process that holds no candidate facet counts one evaluation per step)
    evaluations = problem.dem.comm.allreduce(stepper.force_evaluations, op=MPI.MAX)
    assert evaluations > stepper.n + 4  # measured 413 evaluations in 400 steps
    assert floor.contact_gap(floor.patch_values(stepper.u))[0] > -1e-12 * 0.02
    assert problem.contacts == (floor,)
