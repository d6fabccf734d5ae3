"""sim: the virtual world.

Risley-prism scan model, UAV targets, scenes and effects, ray casting, the closed loop in virtual
time, and virtual Livox / PTS-303H devices that speak the real protocols.
"""
