"""gimbal: the pan/tilt head.

Pelco-D/P codec, PTS-303H device model, serial transport and client.  Imports neither
``foveatrack`` nor ``sim``.
"""
