"""The accuracy protocol of EVALUATION.md: simulated capture, reconstruction by every
method, errors per joint and per take, text reports and plots.
"""
