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
