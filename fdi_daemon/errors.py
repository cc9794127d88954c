"""The project's error convention.

A `UserError` is a mistake of the user's (a bad file, config, argument or frame): the CLI
prints its message as one line on stderr and exits with code 2, never with a traceback.
Anything else that escapes is a bug in fdi and is allowed to show a traceback.
"""


class UserError(Exception):
    """A problem with the user's input, reported as one clear line (exit code 2)."""

    exit_code = 2


class RecordingError(UserError):
    """A recording file that cannot be read or does not meet the recording contract."""


class ConfigError(UserError):
    """A config, scenario or model file that is malformed; the message names the key."""
