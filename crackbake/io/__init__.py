"""Reading and writing the pipeline's own inputs: asset meshes, images, the crack sidecar."""
