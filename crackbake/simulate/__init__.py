"""Simulation: the sim mesh on the asset's surface (``simmesh``), the stress field (``stress``),
the crack solvers (``solver``: Iben & O'Brien and the thesis variant) and ``setup``, which turns
run parameters into stress sources and solver parameters."""
