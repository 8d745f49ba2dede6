"""User-facing errors: one clear message and an exit code, never a traceback."""


class EmaError(Exception):
    """An error caused by the user's input or environment.

    ``exit_code`` 2 means bad usage or input; 1 means a failure while running.
    """

    def __init__(self, message: str, exit_code: int = 2) -> None:
        super().__init__(message)
        self.message = message
        self.exit_code = exit_code

    def __str__(self) -> str:
        return self.message

    def __reduce__(self) -> tuple[type, tuple[str, int]]:
        """Pickled with its exit code (raised in a worker process, re-raised here)."""
        return (type(self), (self.message, self.exit_code))


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the program runs: it stops as Ctrl-C does (finished work kept,
    temporary files removed), and the command exits 143 (128 + 15) instead of 130."""


SIGNALLED: list[int] = []
"""The signals (SIGINT, SIGTERM) the command line received, in order: an exception raised
after one (a worker process killed by the same signal, say) is reported as the interruption."""
