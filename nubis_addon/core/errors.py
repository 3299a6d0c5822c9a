"""The one exception type users see: its message is a single sentence that says what to do."""


class NubisError(Exception):
    """A user-facing failure. ``str(err)`` is shown as-is on the command line and in operator reports."""
