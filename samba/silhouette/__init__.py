"""Single-camera markerless capture (Okada, Stenger, Kondoh): silhouettes extracted from
video, the shape tree of rendered database poses, and the tree-based tracker.
"""
