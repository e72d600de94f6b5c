"""Argument types and exit codes shared by the commands."""

import argparse
import math

EXIT_BAD_INPUT = 2
"""Exit code of a command given bad input (one line on stderr says what)."""


def number(text):
    """Parse a float (argparse type)."""
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'not a number: {text!r}') from None


def finite(text):
    """Parse a finite float (argparse type)."""
    value = number(text)
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f'must be finite, got {text!r}')
    return value


def tolerance(text):
    """Parse a tolerance: a float >= 0 or inf (argparse type)."""
    value = number(text)
    if not value >= 0.0:
        raise argparse.ArgumentTypeError(f'must be >= 0 (or inf), got {text!r}')
    return value
