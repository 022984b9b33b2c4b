"""DOLFINx finite-element reference solvers, to validate the DEM against."""
