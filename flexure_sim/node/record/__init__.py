"""
The stage node's recordings, written by a helper process.

- ``child``: The recorder process's side of `record_process`.
- ``process``: MCAP recording in a helper process, so writing the file costs the stepping loop no
  GIL time.
- ``session``: Recordings of the stage node.
"""
