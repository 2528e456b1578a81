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


def time_axis_arg(text: str):
    """An argparse type: config `sensor.time_axis` as JSON, parsed to a `TimeAxis`."""
    from denali_pipe.core.geometry import TimeAxis

    d = json_arg(text)
    try:
        return TimeAxis.from_config(d)
    except (KeyError, TypeError, ValueError) as e:
        raise argparse.ArgumentTypeError(f"not a sensor.time_axis block ({type(e).__name__}: {e}): {text[:80]!r}") from None


def add_time_axis(parser: argparse.ArgumentParser, needed_by: str | None = None) -> None:
    """The `--time-axis` argument: config `sensor.time_axis` as JSON (rules/common.smk's
    TIME_AXIS_ARG); required, or optional where only `needed_by` (said in its help) needs it."""
    parser.add_argument(
        "--time-axis",
        type=time_axis_arg,
        required=needed_by is None,
        help='the histograms\' time axis, config sensor.time_axis as JSON {"bin_width_ps": ..., "zero_bin": ...}'
        + (f"; {needed_by} needs it" if needed_by else ""),
    )
