"""dmtrack.viz."""
