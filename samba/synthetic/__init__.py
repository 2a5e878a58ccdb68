"""The built-in motions: procedural takes on the 13-joint skeleton (walk, run, dance, ...),
the pose database when no real motion capture is there.
"""

from samba.synthetic.motions import MOTIONS, generate, library

__all__ = [
    "MOTIONS",
    "generate",
    "library",
]
