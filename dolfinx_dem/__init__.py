"""dolfinx_dem: a cell-centred Discrete Element Method for elastodynamics with contact on DOLFINx."""
