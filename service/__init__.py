"""The live capture service: camera packets in, poses out (VMC/OSC, viewer, MCAP takes).

Empty until the live-service issue lands; present so that the package layout is fixed.
"""
