"""puppet.live."""
