"""Reading and writing files: scene loaders, radiosity PLY output and atomic file writes."""
