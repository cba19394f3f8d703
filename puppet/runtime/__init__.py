"""puppet.runtime."""
