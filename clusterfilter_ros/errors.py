"""Exceptions that carry a message meant for the user (no traceback needed)."""


class ClusterfilterError(Exception):
    """A problem with the user's input or environment, explained in one line.

    The CLI prints ``error: <message>`` and exits with code 2 for these. The message
    should name the culprit (file, topic, parameter) and what was wrong with it.
    """


class InputError(ClusterfilterError):
    """Input data that cannot be read: missing path, corrupt file, unknown topic."""


class ParameterError(ClusterfilterError, ValueError):
    """A parameter value outside its range or of the wrong type."""
