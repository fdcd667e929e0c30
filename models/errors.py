"""Errors a user can fix (bad file, bad parameter, bad connection): the command line prints
them as one line and exits with code 2."""


class UserError(Exception):
    """A problem with the user's input, stated in one line that names the file or element."""
