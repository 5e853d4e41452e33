"""Errors that the command line reports as one line on stderr with exit code 2."""


class EtmpcError(Exception):
    """Bad input from a user (unknown name, bad policy spec, missing or corrupt file)."""


class UnknownNameError(EtmpcError, KeyError):
    """An unknown domain, task or policy name."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0])


class TestSetError(EtmpcError):
    """A stored test set is missing, corrupted or belongs to another task."""

    __test__ = False  # not a pytest test class


class Terminated(BaseException):
    """SIGTERM, turned into an orderly stop by the command line: workers shut down, partial files removed."""
