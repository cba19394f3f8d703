"""puppet.bench."""
