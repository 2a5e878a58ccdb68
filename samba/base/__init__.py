"""What every Samba package stands on: the error types a user sees (`SambaError`,
`InputError`), atomic file writes, and the command-line argument types.
"""
