"""Files for other tools: EXR, PNG and GLB writers and the atomic output folder."""
