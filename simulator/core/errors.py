"""The package's exceptions.

Every user error (bad file, bad option, bad data) raises :class:`InputError`; the CLI
turns it into one line on stderr and exit status 2. Anything else is an internal error
(exit status 1).
"""

from __future__ import annotations

__all__ = ["InputError", "VimsimError"]


class VimsimError(Exception):
    """Base class of vimsim's exceptions."""


class InputError(VimsimError, ValueError):
    """Bad input from the user: a file, an option or data that cannot be used.

    The message is one line naming the file (where there is one), the problem and what
    was expected, e.g. ``"head path p.csv: column 'yaw_deg' missing; found ['t', 'yaw']"``.
    """
