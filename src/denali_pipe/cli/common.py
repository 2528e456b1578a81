"""What every `denali` verb shares: JSON arguments and their checks."""

from __future__ import annotations

import argparse
import json


def json_arg(text: str):
    """An argparse type: the argument parsed as JSON."""
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise argparse.ArgumentTypeError(f"not valid JSON ({e}): {text[:80]!r}") from None


def require_keys(config: dict, keys: set[str]) -> None:
    """Refuse a --config JSON that lacks any of `keys`."""
    missing = keys - set(config)
    if missing:
        raise ValueError(f"--config lacks the keys {sorted(missing)}")
