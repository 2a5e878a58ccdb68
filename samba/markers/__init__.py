"""The marker chain: blob detection, 2D tracking, cross-view and leg labelling, stage
tracking and the search for the standard pose, plus the synthetic marker cameras.
"""
