"""puppet.fap."""
