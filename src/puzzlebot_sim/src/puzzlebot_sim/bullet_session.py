"""Ownership of a PyBullet physics client and its temporary URDF directory."""

import tempfile

import pybullet as pb


class BulletSession:
    """Base of the objects that own a physics client (SimWorld, ForceRig).

    ``_connect`` opens the client (DIRECT, or GUI) and a temporary directory
    for generated URDF files; ``close`` (also on leaving a ``with`` block)
    disconnects and removes the directory, and may be called more than once.
    """

    client = None
    _tmp = None

    def _connect(self, gui=False, tmp_prefix="puzzlebot_"):
        self.client = pb.connect(pb.GUI if gui else pb.DIRECT)
        self._tmp = tempfile.TemporaryDirectory(prefix=tmp_prefix)
        return self.client

    def close(self):
        if self.client is not None and pb.isConnected(physicsClientId=self.client):
            pb.disconnect(physicsClientId=self.client)
        self.client = None
        if self._tmp is not None:
            self._tmp.cleanup()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
