"""Dynamic fracture along facets (issue 34), first brick: the crack state, the split geometry,
the operator of a crack set and the energy release rate G_h at fixed displacements. Serial;
not yet wired into MEMM (design note ``design_34_fracture.md`` §2, next stage).

- ``CrackState``, ``split_geometry`` (crack.py): broken facets become two boundary facets;
- ``Conditions``, ``compute_operator`` (operator.py): R and Q = [S; J] of a crack set from
  scratch, in the intact operator's row layout; ``break_facets`` (rebuild.py): the same, rebuilt
  locally when facets break;
- ``energy_release``, ``potential_drop`` (release.py): G_h(f) = [V(u; C) - V(u; C + {f})] / |f|.
"""

from dolfinx_dem.fracture.crack import CrackState, split_geometry
from dolfinx_dem.fracture.operator import Conditions, CrackedOperator, compute_operator
from dolfinx_dem.fracture.rebuild import break_facets
from dolfinx_dem.fracture.release import energy_release, potential_drop

__all__ = ["Conditions", "CrackState", "CrackedOperator", "break_facets", "compute_operator", "energy_release",
           "potential_drop", "split_geometry"]
