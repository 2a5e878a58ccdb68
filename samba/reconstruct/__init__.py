"""13 joints from 8 markers: the Samba paper's reconstruction (retrieval, pseudo-poses, local
pose space, energy solve), our part retrieval, and the named method presets.
"""
