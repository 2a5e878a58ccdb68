"""The 13-joint body: joints, the 8-marker set, bones, kinematics, canonical alignment,
takes, and the capsule body model of the markerless modes.
"""
