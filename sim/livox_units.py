"""What a virtual Livox unit is, per scanner preset: device type, broadcast code, firmware, data types,
IMU, fan, return modes, configuration keys (what :class:`sim.virtual_lidar.VirtualLivox` tells a host).

Sources: Livox SDK 2.3.0 ``livox_def.h`` (device types, data types, return modes, IMU frequency,
parameter keys), ``command_impl.cpp`` (which unit the SDK itself lets take which command: fan and IP
mode not on Mid-40, high sensitivity on Tele-15/Avia, scan pattern on Avia, slot number on
Mid-70/Avia), the SDK README (broadcast code = 14-character serial + digit 1, or 1/2/3 for a Mid-100's
left/middle/right units) and facts/livox.md (Mid-40 sends types 0/1, Horizon/Tele extended types; IMU
on Horizon, Tele-15 and Avia, none on Mid-40/70/100).

The serial numbers and firmware versions here are made up (a virtual unit has none): they have the
real form (``0TF...``-like 14 characters; firmware AA.BB.CC.DD) and versions at or above the ones the
SDK and the protocol notes name as minimums (Mid-40 03.07.0000 for reboot and time-sync status).
They are not claims about real releases.  Avoid Mid-40 firmware 03.03.0001/2/6/7: drivers read those as
the multi-return special firmwares.

Keyed by the preset name of ``sim/scan/presets.py``.  The table also covers presets that file may not
have yet; :func:`unit_for_preset` falls back to a Horizon-like unit for a name it does not know (its
``fallback`` attribute says so, and the CLI prints it).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from foveatrack.livox import protocol as P

#: (coordinate system 0 Cartesian / 1 spherical, returns per slot) -> data type (``PointDataType``)
MID_TYPES = {(0, 1): 0, (1, 1): 1}
EXTENDED_TYPES = {(0, 1): 2, (1, 1): 3, (0, 2): 4, (1, 2): 5}
EXTENDED_TRIPLE_TYPES = {**EXTENDED_TYPES, (0, 3): 7, (1, 3): 8}

#: returns per slot of each return mode (0 first, 1 strongest, 2 dual, 3 triple)
RETURNS_OF_MODE = {0: 1, 1: 1, 2: 2, 3: 3}


@dataclass(frozen=True)
class LivoxUnit:
    """One model of Livox SDK v1 lidar as the virtual lidar presents it.

    model : str, the vendor's name; dev_type : int (``DeviceType``: Mid-40 1, Tele 2, Horizon 3,
    Mid-70 6, Avia 7); serial : 14 ASCII letters/digits; firmware : (AA, BB, CC, DD);
    data_types : {(coordinate system, returns per slot): data type};
    return_modes : the return modes it accepts (0 first, 1 strongest, 2 dual, 3 triple);
    has_imu / has_fan / rain_fog : it takes the IMU-frequency / fan / rain-fog commands;
    param_keys : configuration keys it reads and writes {key: default value bytes};
    heads : units in one product (3 for the Mid-100, broadcast codes ending 1, 2, 3);
    fallback : True when the preset was unknown and this is the generic unit.
    """

    model: str
    dev_type: int
    serial: str
    firmware: tuple[int, int, int, int]
    data_types: dict = field(default_factory=lambda: dict(EXTENDED_TYPES))
    return_modes: tuple[int, ...] = (0, 1, 2)
    has_imu: bool = False
    has_fan: bool = False
    rain_fog: bool = False
    param_keys: dict = field(default_factory=dict)
    heads: int = 1
    fallback: bool = False

    def broadcast_code(self, head: int = 1) -> str:
        return P.make_broadcast_code(self.serial, head)

    def data_type(self, coordinate_system: int = 0, return_mode: int = 0) -> int | None:
        """Data type for a coordinate system and return mode; None if this unit has none (or this
        build of the protocol module cannot encode it)."""
        dt = self.data_types.get((coordinate_system, RETURNS_OF_MODE.get(return_mode, 0)))
        return dt if dt in P.POINT_DATA_TYPES else None

    def mode_of_data_type(self, data_type: int) -> tuple[int, int] | None:
        """(coordinate system, return mode) that gives ``data_type`` (first/strongest -> first)."""
        for (cs, n), dt in self.data_types.items():
            if dt == data_type:
                return cs, {1: 0, 2: 2, 3: 3}[n]
        return None


MID40 = LivoxUnit("Mid-40", 1, "0FTSIMM4000001", (3, 8, 0, 0), dict(MID_TYPES), (0, 1), rain_fog=True)
MID100 = replace(MID40, model="Mid-100", serial="0FTSIMM1000001", heads=3)
MID70 = LivoxUnit("Mid-70", 6, "0FTSIMM7000001", (10, 3, 0, 0), dict(EXTENDED_TYPES), (0, 1, 2),
                  param_keys={P.PARAM_KEY_SLOT_NUM: b"\x01"})
HORIZON = LivoxUnit("Horizon", 3, "0FTSIMHZ000001", (6, 11, 0, 0), dict(EXTENDED_TYPES), (0, 1, 2),
                    has_imu=True, has_fan=True)
TELE15 = LivoxUnit("Tele-15", 2, "0FTSIMTL000001", (7, 9, 0, 0), dict(EXTENDED_TYPES), (0, 1, 2),
                   has_imu=True, has_fan=True, param_keys={P.PARAM_KEY_HIGH_SENSITIVITY: b"\x01"})
AVIA = LivoxUnit("Avia", 7, "0FTSIMAV000001", (11, 6, 0, 0), dict(EXTENDED_TRIPLE_TYPES), (0, 1, 2, 3),
                 has_imu=True, has_fan=True,
                 param_keys={P.PARAM_KEY_HIGH_SENSITIVITY: b"\x01", P.PARAM_KEY_SCAN_PATTERN: b"\x00",
                             P.PARAM_KEY_SLOT_NUM: b"\x01"})

#: scanner preset name -> unit ("prototype" is the paper's Mid-40-like scanner)
UNITS: dict[str, LivoxUnit] = {
    "prototype": MID40, "mid40": MID40, "mid100": MID100, "mid70": MID70,
    "horizon": HORIZON, "tele15": TELE15, "avia": AVIA,
}

GENERIC = replace(HORIZON, model="Horizon (generic)", fallback=True)


def unit_for_preset(name: str) -> LivoxUnit:
    """The unit of scanner preset ``name``; a Horizon-like unit with ``fallback=True`` if unknown."""
    return UNITS.get(name, GENERIC)


__all__ = ["LivoxUnit", "UNITS", "GENERIC", "unit_for_preset", "RETURNS_OF_MODE"]
