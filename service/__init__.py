"""The live capture service: camera packets in, poses out (VMC/OSC, viewer, MCAP takes).

`packet` is the camera-node wire format, `vmc` the VMC/OSC output to game engines,
`take_recorder` the MCAP take writer (read back by `samba.ingest.mcap_take`).
"""
