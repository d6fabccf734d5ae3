"""Errors a user can cause (a bad file, port, packet or option).

They carry a message that names what was wrong and are printed without a traceback by the CLI.
Errors a developer caused stay ordinary exceptions and stay loud.
"""


class UserError(Exception):
    """Something the user supplied is wrong; the message says what and what is allowed."""


def owner_names(st) -> tuple[str, str]:
    """The names of a ``stat`` result's owner and group (their numbers where the system has none)."""
    import grp
    import pwd

    try:
        owner = pwd.getpwuid(st.st_uid).pw_name
    except KeyError:
        owner = str(st.st_uid)
    try:
        group = grp.getgrgid(st.st_gid).gr_name
    except KeyError:
        group = str(st.st_gid)
    return owner, group


def access_text(path) -> str:
    """Who may use ``path`` (a link followed), for the message about a file this user may not read or
    write: ``owner root, group dialout, mode 660``; "" where it cannot be said."""
    import os
    import stat

    try:
        st = os.stat(path)
    except OSError:
        return ""
    owner, group = owner_names(st)
    return f"owner {owner}, group {group}, mode {stat.S_IMODE(st.st_mode):03o}"
