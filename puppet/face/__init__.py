"""puppet.face."""
