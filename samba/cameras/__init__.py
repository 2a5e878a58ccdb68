"""Cameras: the calibrated camera model, calibration from boards (bundle adjustment, files
of other tools), the frames of a camera, and triangulation.
"""
