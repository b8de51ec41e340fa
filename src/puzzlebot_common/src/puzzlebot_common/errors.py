"""Exceptions shared by the stack."""


class ConfigError(ValueError):
    """A configuration file or parameter is malformed.

    The message names the offending entry (e.g. ``robots[2].name``) and says
    what was expected, so that a node can log it and exit without a traceback.
    """
