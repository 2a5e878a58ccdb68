"""The live service's `samba` subcommands, one module each: `serve`, `node`, `demo`,
`track-video`, `capture-volume`, `reconstruct`. Each only parses its arguments, calls the
service API (`samba.service`) and prints what comes back.
"""
