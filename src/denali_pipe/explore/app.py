"""The explorer's Dash app over one results folder: its layout, what the
controls may select, and the callbacks that redraw the panels.

The folder is scanned again on every page load and every redraw, so
outputs built while the explorer runs appear on the next change; nothing is
written anywhere.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from dash import Dash, Input, Output, ctx, dcc, html

from denali_pipe.core import geometry as geo
from denali_pipe.core.capture_sets import LIGHTINGS, CaptureSet, background_of, parse_set_name
from denali_pipe.core.objects import BACKGROUNDS, SIZES
from denali_pipe.core.splits import SPLITS
from denali_pipe.explore import capture as cap
from denali_pipe.explore import figures as figs
from denali_pipe.explore.outputs import (
    ALL_STORES,
    BENCHMARK_CELLS,
    POSITIONS,
    TRANSFORMS,
    CellChoice,
    Inventory,
    Missing,
    benchmark_objects,
    crop_path,
    dataset_paths,
    features_path,
    index_path,
    scan,
    store_path,
    target,
    twin_path,
)  # fmt: skip
from denali_pipe.explore.predictions import ERROR_METRIC, capture_output, error_by_location, trained_cell
from denali_pipe.train.cells import PROTOCOLS

log = logging.getLogger(__name__)

TASKS = tuple(ERROR_METRIC)  # location, shape, size
TOP_SHAPES = 5
# Where a fresh page starts, as the reference GUI does (8 in, lights on,
# mid-gantry; we prefer 3x3, the benchmark's resolution, and the 1D CNN
# under the paper's random split, the cells of Table 5's first row).
START = {"size": "8inch", "resolution": "3x3", "light": "lighton", "location": 50, "protocol": PROTOCOLS[0], "split": SPLITS[0], "model": "cnn1d"}
# Per theme: the Plotly template and the page's style; the dark one also
# sets the Dash components' colour variables (their defaults are for a light page).
THEMES = {
    "light": ("plotly_white", {"backgroundColor": "#ffffff", "color": "#222222"}),
    "dark": ("plotly_dark", {
        "backgroundColor": "#111111", "color": "#dddddd",
        "--Dash-Fill-Inverse-Strong": "#222222", "--Dash-Text-Primary": "rgba(255, 255, 255, 0.87)", "--Dash-Text-Strong": "rgba(255, 255, 255, 0.9)",
        "--Dash-Text-Weak": "rgba(255, 255, 255, 0.65)", "--Dash-Text-Disabled": "rgba(255, 255, 255, 0.4)", "--Dash-Stroke-Strong": "rgba(255, 255, 255, 0.45)",
        "--Dash-Stroke-Weak": "rgba(255, 255, 255, 0.15)", "--Dash-Fill-Disabled": "rgba(255, 255, 255, 0.1)", "--Dash-Fill-Interactive-Weak": "rgba(255, 255, 255, 0.06)",
    }),
}  # fmt: skip
PAGE_STYLE = {"fontFamily": "sans-serif", "padding": "8px 16px", "minHeight": "100vh"}
PANEL_STYLE = {"height": "430px"}
# Slider labels: at most this many, the other captured locations unlabelled ticks.
MAX_LABELS = 13


@dataclass(frozen=True)
class Selection:
    """The capture shown: a set, a gantry location, a repeat."""

    cs: CaptureSet
    location: int
    repeat: int


# --- what the controls may select -----------------------------------------------------------


def pick_set(sets: tuple[CaptureSet, ...], obj: str | None, size: str | None, res: str | None, light: str | None) -> CaptureSet | None:
    """The object's set that matches the wanted size, then resolution, then
    lighting best (a control whose value the object lacks moves to what it
    has; ties go to the first set by name)."""
    own = [s for s in sets if s.object == obj]
    if not own:
        return None
    return max(own, key=lambda s: (s.size == size, s.resolution == res, s.light == light))


def pick_choice(choices: list[CellChoice], protocol: str | None, split: str | None, model: str | None, seed: int | None) -> CellChoice | None:
    """The cell choice that matches the wanted protocol, then split, model and seed best."""
    if not choices:
        return None
    return max(choices, key=lambda c: (c.protocol == protocol, c.split == split, c.model == model, c.seed == seed))


def radio_options(values: tuple[str, ...], available: set[str]) -> list[dict]:
    return [{"label": v, "value": v, "disabled": v not in available} for v in values]


def object_options(inv: Inventory) -> list[dict]:
    """The captured objects: the benchmark's first, then held-out variants,
    then backgrounds (the benchmark datasets say which are which; without
    them the objects are not told apart)."""
    base = benchmark_objects(inv)

    def group(obj: str) -> tuple[int, str]:
        if obj in BACKGROUNDS:
            return 2, " (background)"
        if base is None or obj in base:
            return 0, ""
        return 1, " (held-out variant)"

    ranked = sorted((group(o), o) for o in {s.object for s in inv.sets})
    return [{"label": o + suffix, "value": o} for (_, suffix), o in ranked]


def location_marks(locations: np.ndarray) -> dict:
    """Slider marks at the captured locations, at most MAX_LABELS of them labelled."""
    every = -(-len(locations) // MAX_LABELS)
    return {int(k): str(int(k)) if i % every == 0 else "" for i, k in enumerate(locations)}


def nearest(values: np.ndarray, wanted: int | None) -> int:
    return int(values[np.argmin(np.abs(values - (START["location"] if wanted is None else wanted)))])


# --- the layout ---------------------------------------------------------------------------------


def banner(missing: list[Missing]) -> html.Div:
    """What the results folder lacks, each with the command that builds it."""
    if not missing:
        return html.Div(id="missing")
    items = [html.Li([m.what, ": ", html.Code(m.command)] if m.command else m.what) for m in missing]
    return html.Div(
        id="missing",
        children=[html.Strong("Missing outputs (run in the workflow's folder, with the --configfile it ran with):"), html.Ul(items)],
        style={"border": "1px solid #d73027", "padding": "4px 12px", "margin": "6px 0"},
    )


def _labelled(label: str, control) -> html.Div:
    return html.Div(
        [html.Label(label, style={"fontWeight": "bold", "marginRight": "6px"}), control],
        style={"display": "inline-block", "marginRight": "18px", "verticalAlign": "middle"},
    )


def _radio(id_: str, values: tuple[str, ...], value: str) -> dcc.RadioItems:
    return dcc.RadioItems(id=id_, options=radio_options(values, set(values)), value=value, inline=True, inputStyle={"marginRight": "3px", "marginLeft": "8px"})


def _dropdown(id_: str, width: str) -> dcc.Dropdown:
    return dcc.Dropdown(id=id_, clearable=False, style={"width": width, "display": "inline-block", "verticalAlign": "middle"})


def _panel(id_: str) -> dcc.Graph:
    return dcc.Graph(id=id_, style=PANEL_STYLE, config={"displaylogo": False})


READOUT = ("location", "shape", "size")  # the readout table's rows
PANELS = ("frame", "histograms", "centre", "shape", "size-bars", "grid")  # the graphs, in the page's order


def layout(root: Path) -> html.Div:
    inv = scan(root)
    options = object_options(inv)
    first = next((o["value"] for o in options if o["value"] not in BACKGROUNDS), options[0]["value"] if options else None)
    return html.Div(
        id="page",
        style=PAGE_STYLE,
        children=[
            html.H3(f"DENALI capture explorer: {root}"),
            banner(inv.missing()),
            html.Div(
                [
                    _labelled("object", dcc.Dropdown(id="object", options=options, value=first, clearable=False, style={"width": "320px"})),
                    _labelled("size", _radio("size", tuple(SIZES), START["size"])),
                    _labelled("resolution", _radio("resolution", tuple(geo.RESOLUTIONS), START["resolution"])),
                    _labelled("lighting", _radio("light", LIGHTINGS, START["light"])),
                    _labelled("repeat", dcc.RadioItems(id="repeat", inline=True, value=0, inputStyle={"marginRight": "3px", "marginLeft": "8px"})),
                ]
            ),
            html.Div(
                [
                    _labelled("cell: protocol", _dropdown("protocol", "90px")),
                    _labelled("split", _dropdown("split", "170px")),
                    _labelled("model", _dropdown("model", "120px")),
                    _labelled("seed", _dropdown("seed", "80px")),
                    _labelled("heat map", _radio("heat", TASKS, TASKS[0])),
                    _labelled("histograms", _radio("yscale", ("linear", "log"), "log")),
                    _labelled("theme", _radio("theme", tuple(THEMES), "light")),
                ],
                style={"marginTop": "6px"},
            ),
            html.Div(
                [
                    html.Label("gantry location", style={"fontWeight": "bold", "marginRight": "6px"}),
                    # a step to the previous or next captured location, as the reference GUI's frame buttons
                    html.Button("◀", id="previous", title="previous captured location"),
                    html.Button("▶", id="next", title="next captured location"),
                    dcc.Slider(id="location", min=0, max=geo.N_LOCATIONS - 1, step=None, marks={}, value=START["location"]),
                ],
                style={"marginTop": "6px"},
            ),
            dcc.Store(id="selection"),
            html.Div(id="messages"),
            html.Table(
                id="readout",
                children=[
                    html.Tr([html.Th(h) for h in ("", "ground truth", "prediction", "")]),
                    *[html.Tr([html.Th(task), html.Td(id=f"truth-{task}"), html.Td(id=f"pred-{task}"), html.Td(id=f"note-{task}")]) for task in READOUT],
                ],
                style={"margin": "6px 0", "fontSize": "14px"},
            ),
            html.Div(
                [_panel(p) for p in PANELS],
                style={"display": "grid", "gridTemplateColumns": "repeat(3, minmax(0, 1fr))", "gap": "6px"},
            ),
        ],  # fmt: skip
    )


# --- drawing one selection ----------------------------------------------------------------------


@dataclass
class Outputs:
    """A cell choice's outputs for the selected capture: per task (2,)
    metres or (C,) class probabilities, with the class names; `missing`
    says why a task has none."""

    values: dict[str, np.ndarray]
    classes: dict[str, list[str]]
    missing: dict[str, Missing]

    @classmethod
    def none(cls, why: Missing) -> Outputs:
        return cls({}, {}, {task: why for task in TASKS})


def cell_outputs(inv: Inventory, sel: Selection, choice: CellChoice | None) -> Outputs:
    """The choice's location, shape and size cells on the selected repeat's
    input: its features (clean), or its raw counts (paper, as those cells train)."""
    res = sel.cs.resolution
    if sel.cs.is_background:
        return Outputs.none(Missing("a background set: nothing to predict", ""))
    if choice is None:
        if not inv.cells:
            return Outputs.none(Missing("no training cells", target(BENCHMARK_CELLS)))
        # the workflow trains at train.resolution only; a cell at another one is built by its path
        seed = min(c.seed for c, _ in inv.cells)
        run = CellChoice(START["protocol"], res, START["split"], START["model"], seed).run_path(TASKS[0])
        return Outputs.none(Missing(f"no training cell at {res}", target(f"{run}/metrics.json") + " (and likewise the shape and size cells)"))
    if choice.protocol == "paper":
        x = cap.raw_histograms(cap.capture_store(inv, sel.cs), sel.location)[sel.repeat].astype(np.float32)
    elif sel.cs.name not in inv.features:
        return Outputs.none(Missing(f"no features for {sel.cs.name} (the models' input)", target(features_path(sel.cs.name))))
    else:
        x = cap.capture_features(inv, sel.cs, sel.location)[0][sel.repeat]
    out = Outputs({}, {}, {})
    for task in TASKS:
        status = inv.cell_status(choice, task)
        if status is not None:
            out.missing[task] = status
            continue
        trained = trained_cell(inv, choice, task)
        out.values[task] = capture_output(trained, x)
        out.classes[task] = trained.classes
    return out


def _safe(draw, template: str):
    """Draw a panel; one that cannot be drawn says why and leaves the others
    (an output written by another version, a truncated file)."""
    try:
        return draw()
    except Exception as e:  # noqa: BLE001 -- any failure of one panel is shown in it, with the traceback logged
        log.exception("panel failed")
        return figs.message_figure(f"cannot draw: {type(e).__name__}: {e}"[:300], template)


def _truth(inv: Inventory, location: int):
    """(x, y, z) of tag 1 at a location, None when not calibrated there."""
    if not inv.calibrated:
        return None
    positions = cap.read_calibration(inv).positions
    return positions.loc[location].to_numpy() if location in positions.index else None


def frame_panel(inv: Inventory, sel: Selection, outputs: Outputs, template: str):
    store = cap.capture_store(inv, sel.cs)
    rgb = cap.tracking_frame(store, sel.location)
    if rgb is None:
        return figs.message_figure(f"{sel.cs.name} has no tracking frames", template)
    if not inv.calibrated:
        return figs.frame_figure(rgb, None, None, figs.title("Tracking frame", f"no calibration: {target(POSITIONS)}"), template)
    cal, truth = cap.read_calibration(inv), _truth(inv, sel.location)
    size = (rgb.shape[1], rgb.shape[0])
    truth_uv = None if truth is None else cal.pixels(truth[None], size)[0]
    predicted_uv, detail = None, "no location prediction"
    if "location" in outputs.values and truth is not None:
        xy = outputs.values["location"]
        # drawn on the gantry's plane at the label's height: the models predict x, y only
        predicted_uv = cal.pixels(np.array([[xy[0], xy[1], truth[2]]]), size)[0]
        detail = f"error {100 * np.hypot(*(xy - truth[:2])):.1f} cm (the prediction drawn at the label's height)"
    return figs.frame_figure(rgb, truth_uv, predicted_uv, figs.title(f"Tracking frame, location {sel.location}", detail), template)


def histograms_panel(inv: Inventory, sel: Selection, log_y: bool, axis: geo.TimeAxis, template: str):
    counts = cap.raw_histograms(cap.capture_store(inv, sel.cs), sel.location)[sel.repeat]
    bg_set, background = background_of(sel.cs), None
    if inv.has_set(bg_set):
        bg_store = cap.capture_store(inv, bg_set)
        if sel.location in bg_store.locations:
            background = cap.background_mean(bg_store, sel.location)
    window = cap.crop_window(inv, sel.cs.resolution)
    n = sel.cs.n_zones
    detail = f"dotted: {bg_set.name}'s mean" if background is not None else f"no background: {target(store_path(bg_set.name))}"
    detail += "; dashed: each zone's first kept bin" if window is not None else f"; no crop window: {target(crop_path(sel.cs.resolution))}"
    zone_starts = None if window is None else window.zone_starts
    return figs.histogram_grid(counts, background, zone_starts, log_y, axis, figs.title(f"Raw {n}x{n} histograms, repeat {sel.repeat}", detail), template)


# The twin's lobe and footprints are calibrated on the benchmark's (retroreflective)
# objects; a non-RR variant's twin is a Lambertian plate with those footprints.
TWIN_NOTE = "dashed: the calibrated twin after the centre zone's scale and blur fitted on the benchmark's objects"


def centre_panel(inv: Inventory, sel: Selection, axis: geo.TimeAxis, template: str):
    if sel.cs.is_background:
        return figs.message_figure("a background set: no background-subtracted features", template)
    if sel.cs.name not in inv.features:
        return figs.message_figure(f"no features: {target(features_path(sel.cs.name))}", template)
    feats, first_bin = cap.capture_features(inv, sel.cs, sel.location)
    n = sel.cs.n_zones
    if n % 2:
        zones, main, detail = [(n // 2, n // 2)], "Centre zone, preprocessed", TWIN_NOTE
    else:
        # no single centre zone: the four around the centre; the twin models the 3x3 centre zone only
        zones, main, detail = (
            [(r, c) for r in (n // 2 - 1, n // 2) for c in (n // 2 - 1, n // 2)],
            "Central 2x2 zones, preprocessed",
            "no twin: it models the 3x3 centre zone",
        )
    twin = None
    if n == 3:
        if (sel.cs.object, sel.cs.size) not in inv.twins:
            detail = f"no twin: {target(twin_path(sel.cs.object, sel.cs.size))}"
        elif not inv.transforms:
            detail = f"no transforms: {target(TRANSFORMS)}"
        else:
            twin = cap.twin_histogram(inv, sel.cs.object, sel.cs.size, sel.location)[first_bin : first_bin + feats.shape[-1]]
    repeats = np.stack([feats[:, r, c] for r, c in zones], axis=1)
    return figs.centre_figure(first_bin, repeats, sel.repeat, twin, [f"zone ({r},{c})" for r, c in zones], axis, figs.title(main, detail), template)


def bars_panel(task: str, outputs: Outputs, truth: str | None, template: str):
    if task not in outputs.values:
        return figs.message_figure(outputs.missing[task].what, template)
    probs, classes = outputs.values[task], outputs.classes[task]
    top = TOP_SHAPES if task == "shape" else len(classes)
    predicted = classes[int(np.argmax(probs))]
    if truth is None:
        rank = "unknown"
    elif truth in classes:
        rank = f"rank {1 + int((probs > probs[classes.index(truth)]).sum())} of {len(classes)}"
    else:
        rank = "a class the cell never learnt"
    heading = figs.title(f"{task.capitalize()}: predicted {predicted}", f"truth {truth} ({rank}); green: the truth's bar")
    return figs.bars_figure(classes, probs, truth, top, heading, template)


def grid_panel(inv: Inventory, sel: Selection, choice: CellChoice | None, heat: str, outputs: Outputs, template: str):
    if not inv.calibrated:
        return figs.message_figure(f"no calibration: {target(POSITIONS)}", template)
    cal = cap.read_calibration(inv)
    grid = cap.gantry_grid(cal.positions)
    error, label, detail = None, "", f"no {heat} test error"
    if choice is not None and inv.cell_status(choice, heat) is None and (choice.protocol, choice.resolution) in inv.datasets:
        _, name, unit = ERROR_METRIC[heat]
        error, label = error_by_location(inv, choice, heat), f"{name} ({unit})"
        detail = f"colour: the {choice.model} {heat} cell's test {name} per location ({choice.split}, seed {choice.seed})"
    truth = _truth(inv, sel.location)
    predicted = outputs.values.get("location")
    captured = cap.capture_store(inv, sel.cs).locations
    heading = figs.title("Gantry grid: click a location", detail)
    return figs.grid_figure(grid, captured, error, label, None if truth is None else truth[:2], predicted, sel.location, heading, template)


def readout(inv: Inventory, sel: Selection, outputs: Outputs, shape_truth: str | None) -> list:
    """The readout table's cells, row by row: truth, prediction, note."""
    truth = _truth(inv, sel.location)
    cells = []
    xy = outputs.values.get("location")
    cells += [
        "not calibrated" if truth is None else f"x {truth[0]:.4f} m, y {truth[1]:.4f} m",
        "" if xy is None else f"x {xy[0]:.4f} m, y {xy[1]:.4f} m",
        "" if xy is None or truth is None else f"error {100 * np.hypot(*(xy - truth[:2])):.1f} cm",
    ]
    for task, true in (("shape", shape_truth), ("size", sel.cs.size)):
        p = outputs.values.get(task)
        best = None if p is None else int(np.argmax(p))
        cells += [true or "", "" if p is None else outputs.classes[task][best], "" if p is None else f"p = {100 * p[best]:.1f} %"]
    return cells


def messages(items: list[Missing]) -> list:
    return [html.Div(["⚠ ", m.what, *([": ", html.Code(m.command)] if m.command else [])]) for m in items]


# --- the app ----------------------------------------------------------------------------------


def build_app(root: Path, axis: geo.TimeAxis) -> Dash:
    """The explorer over `root` (a results folder, which may be empty or
    absent), its captures on `axis`."""
    root = Path(root)
    app = Dash(__name__, title="DENALI explorer")
    app.layout = lambda: layout(root)

    @app.callback(
        Output("size", "options"), Output("size", "value"),
        Output("resolution", "options"), Output("resolution", "value"),
        Output("light", "options"), Output("light", "value"),
        Output("location", "marks"), Output("location", "value"), Output("location", "disabled"),
        Output("repeat", "options"), Output("repeat", "value"),
        Output("selection", "data"),
        Input("object", "value"), Input("size", "value"), Input("resolution", "value"), Input("light", "value"),
        Input("location", "value"), Input("repeat", "value"), Input("grid", "clickData"), Input("previous", "n_clicks"), Input("next", "n_clicks"),
    )  # fmt: skip
    def select(obj, size, res, light, location, repeat, click, _previous, _next):
        inv = scan(root)
        cs = pick_set(inv.sets, obj, size, res, light)
        if cs is None:
            none = radio_options(tuple(SIZES), set())
            return none, size, radio_options(tuple(geo.RESOLUTIONS), set()), res, radio_options(LIGHTINGS, set()), light, {}, location, True, [], repeat, None
        own = [s for s in inv.sets if s.object == cs.object]
        store = cap.capture_store(inv, cs)
        locations = np.sort(store.locations)
        if ctx.triggered_id == "grid" and click:
            # grid points carry their location first in customdata; the prediction marker carries none
            data = click["points"][0].get("customdata")
            location = location if data is None else data[0] if isinstance(data, list) else data
        location = nearest(locations, location)
        if ctx.triggered_id in ("previous", "next"):
            i = int(np.searchsorted(locations, location)) + (1 if ctx.triggered_id == "next" else -1)
            location = int(locations[min(max(i, 0), len(locations) - 1)])
        repeat = min(int(repeat or 0), store.repeats - 1)
        return (
            radio_options(tuple(SIZES), {s.size for s in own}), cs.size,
            radio_options(tuple(geo.RESOLUTIONS), {s.resolution for s in own if s.size == cs.size}), cs.resolution,
            radio_options(LIGHTINGS, {s.light for s in own if s.size == cs.size and s.resolution == cs.resolution}), cs.light,
            location_marks(locations), location, False,
            [{"label": str(r), "value": r} for r in range(store.repeats)], repeat,
            {"set": cs.name, "location": location, "repeat": repeat},
        )  # fmt: skip

    @app.callback(
        Output("protocol", "options"), Output("protocol", "value"), Output("split", "options"), Output("split", "value"),
        Output("model", "options"), Output("model", "value"), Output("seed", "options"), Output("seed", "value"),
        Input("resolution", "value"), Input("protocol", "value"), Input("split", "value"), Input("model", "value"), Input("seed", "value"),
    )  # fmt: skip
    def choose_cell(res, protocol, split, model, seed):
        choices = scan(root).choices(res)
        c = pick_choice(choices, protocol or START["protocol"], split or START["split"], model or START["model"], seed)
        if c is None:
            return [], None, [], None, [], None, [], None

        def same(*fields):
            """The choices that share the picked one's `fields`."""
            return [o for o in choices if all(getattr(o, f) == getattr(c, f) for f in fields)]

        def opts(values):
            return [{"label": str(v), "value": v} for v in sorted(set(values))]

        return (
            opts(o.protocol for o in choices), c.protocol,
            opts(o.split for o in same("protocol")), c.split,
            opts(o.model for o in same("protocol", "split")), c.model,
            opts(o.seed for o in same("protocol", "split", "model")), c.seed,
        )  # fmt: skip

    @app.callback(Output("page", "style"), Input("theme", "value"))
    def theme(name):
        return {**PAGE_STYLE, **THEMES[name][1]}

    @app.callback(
        *[Output(p, "figure") for p in PANELS],
        *[Output(f"{part}-{task}", "children") for task in READOUT for part in ("truth", "pred", "note")],
        Output("messages", "children"),
        Input("selection", "data"), Input("protocol", "value"), Input("split", "value"), Input("model", "value"), Input("seed", "value"),
        Input("heat", "value"), Input("yscale", "value"), Input("theme", "value"),
    )  # fmt: skip
    def render(selection, protocol, split, model, seed, heat, yscale, theme_name):
        template = THEMES[theme_name][0]
        inv = scan(root)
        if selection is None:
            why = "no capture stores" if not inv.sets else "no capture set selected"
            # the banner says what is missing
            return *[figs.message_figure(f"{why}: {target(ALL_STORES)}", template) for _ in PANELS], *[""] * (3 * len(READOUT)), []
        sel = Selection(parse_set_name(selection["set"]), int(selection["location"]), int(selection["repeat"]))
        res = sel.cs.resolution
        choice = None if protocol is None else CellChoice(protocol, res, split, model, int(seed))
        try:
            outputs = cell_outputs(inv, sel, choice)
        except Exception as e:  # noqa: BLE001 -- a cell or features that cannot be read: shown, the rest still drawn
            log.exception("predictions failed")
            outputs = Outputs.none(Missing(f"cannot predict: {type(e).__name__}: {e}"[:300], ""))
        notes = list(dict.fromkeys(outputs.missing.values()))
        if not inv.calibrated:
            notes.append(Missing("no calibration", target(POSITIONS)))
        if choice is not None and (choice.protocol, res) not in inv.datasets and not sel.cs.is_background:
            notes.append(Missing(f"no {res} {choice.protocol} dataset for the per-location test error", target(dataset_paths(res, choice.protocol)[0])))
        if not (inv.root / crop_path(res)).is_file():
            notes.append(Missing(f"no {res} crop window", target(crop_path(res))))
        shape_truth = None if sel.cs.is_background else cap.object_class(inv, sel.cs)
        if shape_truth is None and not sel.cs.is_background:
            notes.append(Missing(f"no capture index for {sel.cs.name} (its shape class)", target(index_path(sel.cs.name))))
        panels = [
            _safe(lambda: frame_panel(inv, sel, outputs, template), template),
            _safe(lambda: histograms_panel(inv, sel, yscale == "log", axis, template), template),
            _safe(lambda: centre_panel(inv, sel, axis, template), template),
            _safe(lambda: bars_panel("shape", outputs, shape_truth, template), template),
            _safe(lambda: bars_panel("size", outputs, sel.cs.size, template), template),
            _safe(lambda: grid_panel(inv, sel, choice, heat, outputs, template), template),
        ]
        return *panels, *readout(inv, sel, outputs, shape_truth), messages(notes)

    return app


def serve(root: Path, axis: geo.TimeAxis, host: str, port: int) -> None:
    """Serve the explorer over `root` (captures on `axis`) until interrupted."""
    log.info("explorer on http://%s:%d over %s", host, port, Path(root).resolve())
    build_app(root, axis).run(host=host, port=port, debug=False)
