"""Baking: UVs (kept or unwrapped), the headless GL context, the GPU raster of the crack maps."""
