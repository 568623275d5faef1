"""Simulation: the sim mesh on the asset's surface, the stress field, the crack solvers."""
