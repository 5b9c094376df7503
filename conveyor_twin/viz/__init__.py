"""Pictures of cells and recordings (matplotlib) and the live Foxglove view."""
