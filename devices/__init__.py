"""Hardware adapters and simulated devices that yield Samples."""
