"""The explorer's Plotly figures, each from plain arrays.

Every figure takes the Plotly template (light or dark theme) last; a panel
with nothing to show gets `message_figure` with the reason.
"""

from __future__ import annotations

import base64
import functools
import textwrap

import cv2
import numpy as np
import pandas as pd
import plotly.graph_objects as go
import plotly.io as pio

from denali_pipe.core import geometry as geo

TRUTH, PREDICTED, MEASURED, BACKGROUND, TWIN, OTHER = "#1a9850", "#d73027", "#2166ac", "#878787", "#e08214", "#92c5de"
FRAME_JPEG_QUALITY = 90  # the frame travels as a JPEG: a fifth of a PNG's bytes, no visible loss at 640x360
MARGIN = dict(l=55, r=15, t=62, b=45)


def title(main: str, detail: str = "") -> dict:
    """A panel title: a short line (clear of the mode bar on the right) and a smaller line of detail."""
    return dict(text=f"{main}<br><sup>{detail}</sup>" if detail else main, font=dict(size=15), x=0.01, xanchor="left")


MESSAGE_WIDTH = 60  # characters per line of a panel's message: a command and its path fit a third of the page


def message_figure(text: str, template: str) -> go.Figure:
    """An empty panel that says why it is empty."""
    fig = go.Figure(layout=dict(template=template, margin=MARGIN, xaxis=dict(visible=False), yaxis=dict(visible=False)))
    fig.add_annotation(text="<br>".join(textwrap.wrap(text, MESSAGE_WIDTH)), x=0.5, y=0.5, xref="paper", yref="paper", showarrow=False, font=dict(size=14))
    return fig


def frame_figure(rgb: np.ndarray, truth_uv: np.ndarray | None, predicted_uv: np.ndarray | None, heading: dict, template: str) -> go.Figure:
    """The tracking frame (H, W, 3) uint8 RGB with the ground-truth and
    predicted markers at pixel coordinates (u, v) (either may be None)."""
    ok, jpeg = cv2.imencode(".jpg", rgb[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, FRAME_JPEG_QUALITY])
    if not ok:
        raise ValueError(f"could not encode a {rgb.shape} frame as JPEG")
    h, w = rgb.shape[:2]
    fig = go.Figure(go.Image(source="data:image/jpeg;base64," + base64.b64encode(jpeg.tobytes()).decode(), hoverinfo="skip"))
    for name, uv, colour, symbol in (("ground truth", truth_uv, TRUTH, "circle-open"), ("prediction", predicted_uv, PREDICTED, "x-thin-open")):
        if uv is not None:
            fig.add_trace(go.Scatter(x=[uv[0]], y=[uv[1]], name=name, mode="markers", marker=dict(color=colour, size=18, symbol=symbol, line=dict(width=3))))
    fig.update_layout(
        template=template, title=heading, margin=MARGIN, legend=dict(orientation="h", y=-0.02, yanchor="top"),
        xaxis=dict(range=[0, w], visible=False), yaxis=dict(range=[h, 0], visible=False, scaleanchor="x"),
    )  # fmt: skip
    return fig


def _suffix(k: int) -> str:
    """Plotly's name suffix of the k-th subplot's axes (from 1): x, y, then x2, y2, ..."""
    return "" if k == 1 else str(k)


@functools.cache
def _template(name: str) -> dict:
    return pio.templates[name].to_plotly_json()


def histogram_grid(
    counts: np.ndarray, background: np.ndarray | None, zone_starts: np.ndarray | None, log_y: bool, axis: geo.TimeAxis, heading: dict, template: str
) -> dict:
    """The n x n raw histograms (n, n, B) counts of one repeat, the
    background set's mean (n, n, B) overlaid and each zone's first kept bin
    (zone_starts (n, n)) marked; zone (0, 0) top left, as the sensor's grid;
    bins of `axis`.

    A plain figure dict, its axes laid out here: through plotly's figure
    objects (make_subplots and its updates) an 8x8 grid took 0.3-0.6 s to build."""
    n, _, bins = counts.shape
    gap = 0.01
    width = (1 - gap * (n - 1)) / n
    b = np.arange(bins)
    data, shapes = [], []
    layout = dict(template=_template(template), title=heading, margin=MARGIN, showlegend=True, legend=dict(orientation="h", y=-0.14, yanchor="top"))
    for r in range(n):
        for c in range(n):
            first = r == 0 and c == 0
            k = _suffix(r * n + c + 1)
            x0, y1 = c * (width + gap), 1 - r * (width + gap)
            layout[f"xaxis{k}"] = dict(domain=[x0, min(x0 + width, 1.0)], anchor=f"y{k}", showticklabels=r == n - 1, **({} if first else {"matches": "x"}))
            layout[f"yaxis{k}"] = dict(domain=[max(y1 - width, 0.0), y1], anchor=f"x{k}", showticklabels=c == 0, **({} if first else {"matches": "y"}))
            # a log axis labels whole decades only: 2 and 5 between them do not fit an 8x8 grid's subplots
            layout[f"yaxis{k}"].update(dict(type="log", dtick=1) if log_y else dict(type="linear"))
            axes = dict(xaxis=f"x{k}", yaxis=f"y{k}")
            data.append(
                dict(type="scatter", x=b, y=counts[r, c], name="capture", legendgroup="capture", showlegend=first, line=dict(color=MEASURED, width=1), **axes)
            )
            if background is not None:
                data.append(
                    dict(
                        type="scatter",
                        x=b,
                        y=background[r, c],
                        name="background (mean)",
                        legendgroup="bg",
                        showlegend=first,
                        line=dict(color=BACKGROUND, width=1, dash="dot"),
                        **axes,
                    )
                )
            if zone_starts is not None:
                start = int(zone_starts[r, c])
                shapes.append(dict(type="line", xref=f"x{k}", yref=f"y{k} domain", x0=start, x1=start, y0=0, y1=1, line=dict(color=TWIN, width=1, dash="dash")))
    layout[f"xaxis{_suffix((n - 1) * n + (n + 1) // 2)}"]["title"] = dict(text=axis.label())  # the bottom row's middle subplot
    layout[f"yaxis{_suffix(((n + 1) // 2 - 1) * n + 1)}"]["title"] = dict(text=f"counts{' (log)' if log_y else ''}")  # the left column's middle one
    layout["shapes"] = shapes
    return dict(data=data, layout=layout)


def centre_figure(
    first_bin: int, repeats: np.ndarray, chosen: int, twin: np.ndarray | None, names: list[str], axis: geo.TimeAxis, heading: dict, template: str
) -> go.Figure:
    """Background-subtracted cropped counts: repeats (R, K, T) of K zones
    named `names` (the chosen repeat bold, the others faint) from bin
    `first_bin` of `axis`, and the twin's expected counts (T,) of the same bins."""
    t = first_bin + np.arange(repeats.shape[-1])
    fig = go.Figure()
    for k, name in enumerate(names):
        for r in range(len(repeats)):
            bold = r == chosen
            fig.add_trace(go.Scatter(
                x=t, y=repeats[r, k], name=f"{name}, repeat {r}", legendgroup=name, showlegend=bold,
                line=dict(color=MEASURED if len(names) == 1 else None, width=2 if bold else 1), opacity=1.0 if bold else 0.35,
            ))  # fmt: skip
    if twin is not None:
        fig.add_trace(go.Scatter(x=t, y=twin, name="calibrated twin, fitted scale and blur", line=dict(color=TWIN, width=2, dash="dash")))
    fig.add_hline(y=0, line=dict(color=BACKGROUND, width=1))
    fig.update_layout(
        template=template,
        title=heading,
        margin=MARGIN,
        xaxis_title=axis.label(),
        yaxis_title="counts above background",
        legend=dict(orientation="h", y=-0.2, yanchor="top"),
    )
    return fig


def bars_figure(classes: list[str], probabilities: np.ndarray, truth: str | None, top: int, heading: dict, template: str) -> go.Figure:
    """The `top` most probable classes as horizontal bars (most probable on
    top), the ground truth's bar in its own colour."""
    order = np.argsort(-probabilities)[:top]
    names = [classes[i] for i in order]
    colours = [TRUTH if name == truth else OTHER for name in names]
    fig = go.Figure(
        go.Bar(
            x=100 * probabilities[order],
            y=names,
            orientation="h",
            marker_color=colours,
            text=[f"{100 * p:.1f} %" for p in probabilities[order]],
            textposition="auto",
        )
    )
    fig.update_layout(
        template=template, title=heading, margin=MARGIN, xaxis=dict(title="probability (%)", range=[0, 100]),
        yaxis=dict(autorange="reversed", type="category"),
    )  # fmt: skip
    return fig


def grid_figure(
    grid: pd.DataFrame,
    captured: np.ndarray,
    error: pd.DataFrame | None,
    error_label: str,
    truth_xy: np.ndarray | None,
    predicted_xy: np.ndarray | None,
    location: int,
    heading: dict,
    template: str,
) -> go.Figure:
    """The 10 x 10 gantry grid in the world frame (m): `grid`
    (`capture.gantry_grid`) with the set's `captured` locations marked, the
    per-location test error `error` (index location; `value`, `n` test
    samples) as the colour of the locations with test samples, and the
    ground truth and prediction (x, y). Every grid point carries its
    location in `customdata`, first in a row where it has more (a list:
    plotly would send an array as base64, which a click hands back as an
    object of digit keys)."""
    fig = go.Figure()
    other = ~grid["location"].isin(captured)
    fig.add_trace(go.Scatter(
        x=grid["x"][other], y=grid["y"][other], customdata=grid["location"][other], mode="markers", name="not captured in this set",
        marker=dict(color=BACKGROUND, size=5, symbol="circle-open"), hovertemplate="location %{customdata}<extra></extra>",
    ))  # fmt: skip
    here = grid[~other]
    scored = here["location"].isin([] if error is None else error.index)
    fig.add_trace(go.Scatter(
        x=here["x"][~scored], y=here["y"][~scored], customdata=here["location"][~scored], mode="markers", name="captured, no test sample",
        marker=dict(color=BACKGROUND, size=14, symbol="square-open"), hovertemplate="location %{customdata}<extra></extra>",
    ))  # fmt: skip
    if scored.any():
        hit = here[scored]
        e = error.loc[hit["location"]]
        fig.add_trace(go.Scatter(
            x=hit["x"], y=hit["y"], customdata=np.column_stack([hit["location"], e["value"], e["n"]]).tolist(), mode="markers", name="test error",
            marker=dict(color=e["value"], colorscale="Viridis", size=14, symbol="square", colorbar=dict(title=error_label, thickness=12)),
            hovertemplate=f"location %{{customdata[0]}}: {error_label} %{{customdata[1]:.1f}}, %{{customdata[2]}} test samples<extra></extra>",
        ))  # fmt: skip
    if truth_xy is not None:
        fig.add_trace(
            go.Scatter(
                x=[truth_xy[0]],
                y=[truth_xy[1]],
                customdata=[location],
                mode="markers",
                name=f"ground truth (location {location})",
                marker=dict(color=TRUTH, size=22, symbol="circle-open", line=dict(width=3)),
            )
        )
    if predicted_xy is not None:
        fig.add_trace(
            go.Scatter(
                x=[predicted_xy[0]],
                y=[predicted_xy[1]],
                mode="markers",
                name="prediction",
                marker=dict(color=PREDICTED, size=16, symbol="x-thin-open", line=dict(width=3)),
            )
        )
        if truth_xy is not None:
            fig.add_trace(
                go.Scatter(
                    x=[truth_xy[0], predicted_xy[0]],
                    y=[truth_xy[1], predicted_xy[1]],
                    mode="lines",
                    showlegend=False,
                    hoverinfo="skip",
                    line=dict(color=PREDICTED, width=1),
                )
            )
    fig.update_layout(
        template=template, title=heading, margin=MARGIN, legend=dict(orientation="h", y=-0.2, yanchor="top"),
        xaxis=dict(title="x (m)"), yaxis=dict(title="y (m)", scaleanchor="x"),
    )  # fmt: skip
    return fig
