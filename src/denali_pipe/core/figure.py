"""Figures and the table each one plots, written together and atomically.

Importing this module selects matplotlib's file-only Agg backend (jobs have
no display), so figure modules import pyplot from here: `from
denali_pipe.core.figure import plt, save_figure`.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402

from denali_pipe.core.atomic import atomic_file  # noqa: E402

DPI = 110

__all__ = ["plt", "save_figure"]


def save_figure(
    fig: plt.Figure, png: Path, table: pd.DataFrame | None = None, csv: Path | None = None, dpi: int = DPI, float_format: str | None = None
) -> None:
    """Write `fig` to `png` and close it; write `table` (the numbers the
    figure plots) to `csv`, by default the PNG's path with `.csv`, floats as
    `float_format` (pandas' default: every digit). Each file appears
    complete or not at all."""
    png = Path(png)
    if table is not None:
        with atomic_file(Path(csv) if csv is not None else png.with_suffix(".csv")) as tmp:
            table.to_csv(tmp, index=False, float_format=float_format)
    with atomic_file(png) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi)
    plt.close(fig)
