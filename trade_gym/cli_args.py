"""What the command-line tools share: a bad argument is one line on stderr and exit status 2, nothing written."""

from __future__ import annotations

import argparse
from collections.abc import Collection
from typing import NoReturn


class UsageError(Exception):
    """A bad argument (or input named by one): reported as one line, exit status 2, before anything is written."""


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose errors raise UsageError (one line, no usage block) instead of exiting."""

    def error(self, message: str) -> NoReturn:
        raise UsageError(message)


SWITCH_WORDS = {"true": (True,), "on": (True,), "1": (True,), "false": (False,), "off": (False,), "0": (False,)}
BOTH_WORD = "both"  # a sweep over both values of a switch


def parse_switch(item: str, names: Collection[str], allow_both: bool = False) -> tuple[str, tuple[bool, ...]]:
    """`--ablation NAME=VALUE` as (name, its values): VALUE true/on/1 or false/off/0 (or `both` when a sweep is
    allowed); a UsageError naming the item otherwise."""
    name, _, value = item.partition("=")
    if name not in names:
        raise UsageError(f"--ablation {item!r}: unknown switch {name!r} (choose from {', '.join(names)})")
    words = SWITCH_WORDS | ({BOTH_WORD: (False, True)} if allow_both else {})
    if value.lower() not in words:
        raise UsageError(f"--ablation {item!r}: value must be true, false or both" if allow_both
                         else f"--ablation {item!r}: value must be true or false")
    return name, words[value.lower()]
