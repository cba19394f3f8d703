"""puppet.io."""
