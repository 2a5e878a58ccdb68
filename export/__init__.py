"""Retargeting of the 13-joint skeleton to humanoid avatars and USD / glTF / BVH writers.

Empty until the export issue lands; present so that the package layout is fixed.
"""
