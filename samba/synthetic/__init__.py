"""The built-in motions: procedural takes on the 13-joint skeleton, the pose database when
no real motion capture is there.
"""
