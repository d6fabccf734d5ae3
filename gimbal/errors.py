"""Errors a user can cause in the gimbal package (a bad byte value, port, option or address).

``gimbal`` imports neither ``foveatrack`` nor ``sim``, so it has its own exception class; the
``foveatrack`` CLI catches it and prints its message as one line (no traceback).  Errors a
developer caused (wrong types, calls out of time order) stay ordinary exceptions.
"""


class GimbalError(Exception):
    """Something the user supplied is wrong; the message says what and what is allowed."""
