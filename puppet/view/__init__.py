"""puppet.view."""
