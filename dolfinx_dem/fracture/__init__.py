"""Dynamic fracture along facets (issue 34): the crack state, the split geometry, the operator
of a crack set, the energy release rate G_h at fixed displacements and the breaks in MEMM runs
with the balance exact (design note ``docs/design/fracture.md`` §1-3, §6). Serial, 1D in runs.

- ``CrackState``, ``split_geometry`` (crack.py): broken facets become two boundary facets;
- ``Conditions``, ``compute_operator`` (operator.py): R and Q = [S; J] of a crack set from
  scratch, in the intact operator's row layout; ``break_facets`` (rebuild.py): the same, rebuilt
  locally when facets break;
- ``energy_release``, ``potential_drop`` (release.py): G_h(f) = [V(u; C) - V(u; C + {f})] / |f|;
- ``Fracture`` (dynamics.py): breaks at MEMM's step boundaries, Gamma booked in the balance.
"""

from dolfinx_dem.fracture.crack import CrackState, split_geometry
from dolfinx_dem.fracture.dynamics import Fracture
from dolfinx_dem.fracture.operator import Conditions, CrackedOperator, compute_operator
from dolfinx_dem.fracture.rebuild import break_facets
from dolfinx_dem.fracture.release import energy_release, potential_drop

__all__ = ["Conditions", "CrackState", "CrackedOperator", "Fracture", "break_facets", "compute_operator",
           "energy_release", "potential_drop", "split_geometry"]
