"""gimbal: the pan/tilt head.

Pelco-D/P codec, PTS-303H device model, serial transport and client.  Imports neither
``foveatrack`` nor ``sim``.

Modules
-------
- :mod:`gimbal.pelco`: pure byte encode/decode of every command (``encode_pan_tilt``,
  ``encode_stop``, presets, absolute sets, queries, replies) and :class:`PelcoCommand`.
- :mod:`gimbal.framing`: byte-fed parsers ``PelcoDParser`` / ``PelcoPParser`` / ``PelcoParser``
  (``feed(bytes, t_s) -> frames``) that resync, reject bad checksums and drop partial frames
  after an inter-byte gap.
- :mod:`gimbal.pts303h`: the device model ``PTS303H`` (exact dynamics in virtual time) and its
  ``HeadParams`` / ``HEAD_FAMILIES``.
- :mod:`gimbal.client`: ``HeadClient``, the tracker's side over any pyserial URL or path.
- :mod:`gimbal.errors`: ``GimbalError``, the user-error class of this package.

Conventions: pan_deg positive = CCW seen from above = LEFT (Pelco "left" increases pan), wrapped
to (-180, 180]; tilt_deg positive = UP (Pelco "up" increases tilt), limited by stops.
"""
