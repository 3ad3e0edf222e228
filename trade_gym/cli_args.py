"""What the command-line tools share: a bad argument is one line on stderr and exit status 2, nothing written."""

from __future__ import annotations

import argparse


class UsageError(Exception):
    """A bad argument (or input named by one): reported as one line, exit status 2, before anything is written."""


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose errors raise UsageError (one line, no usage block) instead of exiting."""

    def error(self, message: str) -> None:
        raise UsageError(message)
