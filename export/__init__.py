"""Retargeting of the 13-joint skeleton to humanoid avatars, the default avatar, and the
USD / glTF / BVH writers (`samba export`)."""
