"""Livox lidar input: the SDK v1 wire protocol (:mod:`.protocol`), a UDP client (:mod:`.client`) and
the Livox Viewer ``.lvx`` file reader (:mod:`.lvx`)."""

from foveatrack.livox.protocol import DataDecoder, PacketError, PointBatch

__all__ = ["DataDecoder", "PacketError", "PointBatch"]
