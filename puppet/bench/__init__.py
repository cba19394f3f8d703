"""``puppet bench``: what the runtime, the devices and the live pipeline cost, each against a
baseline measured in the same run.
"""
