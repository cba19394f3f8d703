"""What the face looks like: the moderngl renderer, the player and live windows (and the cockpit
drawn over it), takes rendered to video (one or many), the demo, and glTF export.
"""
