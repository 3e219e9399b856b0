"""dmtrack.io."""
