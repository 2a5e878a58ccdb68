"""Multi-camera volumetric capture (Chu, Jenkins, Mataric): visual-hull voxels, Isomap,
spherical shells, a kinematic model common to the sequence, joint angles.
"""
