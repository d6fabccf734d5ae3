"""Errors a user can cause (a bad file, port, packet or option).

They carry a message that names what was wrong and are printed without a traceback by the CLI.
Errors a developer caused stay ordinary exceptions and stay loud.
"""


class UserError(Exception):
    """Something the user supplied is wrong; the message says what and what is allowed."""
