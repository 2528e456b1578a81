# Config loading and validation, capture-set discovery, input functions.
import functools
import json
import shlex
import sys
from types import SimpleNamespace

from snakemake.utils import min_version, validate

from pathlib import Path

import pandas as pd

from denali_pipe.core.capture_sets import FOLDER_SUFFIX, PICKLE_SUFFIX, background_of, expected_sets, parse_set_name, select_sets
from denali_pipe.rig import feature_moments
from denali_pipe.core.splits import SPLITS
from denali_pipe.train.cells import DATASET_DIRS, LINEAR, TASKS, is_ill_posed, uses_gpu
from denali_pipe.workflow.costs import combine, cost_model, frame_pixels, gpu_speedup, load_costs, mem_mb, predict, runtime_minutes, set_work, training_work
from denali_pipe.train.conditions import ALL, PATTERN as CONDITION_PATTERN, TABLES as CONDITION_TABLES, ill_posed, table_conditions
from denali_pipe.train.jitter import RESOLUTION as JITTER_RESOLUTION, jitter_condition, jitter_fwhm
from denali_pipe.core.geometry import N_BINS, N_LOCATIONS, RESOLUTIONS, select_locations
from denali_pipe.io.release_weights import RELEASE_FILES
from denali_pipe.io.tree import survey_tree
from denali_pipe.core.objects import BACKGROUNDS, VARIANTS, load_catalogue
from denali_pipe.train.registry import check_left_out, check_models
from denali_pipe.twin.illumination import check_renderer

min_version("9.0")


configfile: "config/config.yaml"


validate(config, "../config/schema.yaml")
check_renderer(config["twin"]["renderer"], config["twin"]["illumination"])

# The networks to benchmark (train.models, entries set to null left out) and
# the model of the one-model experiments (train.benchmark_model).
MODELS = check_models(config["train"]["models"], config["train"]["benchmark_model"])
BENCHMARK_MODEL = config["train"]["benchmark_model"]
BENCHMARK_LABEL = MODELS[BENCHMARK_MODEL].get("label", BENCHMARK_MODEL)
# The models this preset does not train (train.left_out, {model: reason}):
# Tables 2 and 10 and the speed-vs-accuracy chart print them as absent, with
# the reason; their cells stay targets of their own.
LEFT_OUT = check_left_out(config["train"]["left_out"], config["train"]["models"], BENCHMARK_MODEL)
TRAINED_MODELS = [m for m in MODELS if m not in LEFT_OUT]
LEFT_OUT_ARG = f"--left-out {shlex.quote(json.dumps(LEFT_OUT))}"
# The histograms' time axis (sensor.time_axis), for every verb that turns bins
# into time or path.
TIME_AXIS_ARG = f"--time-axis {shlex.quote(json.dumps(config['sensor']['time_axis'], sort_keys=True))}"

# The rules run `denali <verb>` through the interpreter that runs this
# workflow, so jobs find the project whether or not its venv is activated,
# locally or on cluster nodes that share the venv's path.
DENALI = f"{shlex.quote(sys.executable)} -m denali_pipe.cli"
# The longest serial jobs (the render benchmark, one ~10-min job) and the
# chain ending in Fig 9 (the twin calibration, 67 calibrated twins, the
# transforms, then Fig 9's ~9-min single-thread job) start as soon as their
# inputs exist: left behind the ~170 training cells they would run last,
# alone on one core (Snakemake runs higher-priority ready jobs first).
SERIAL_CHAIN_PRIORITY = 10

CATALOGUE = load_catalogue(config["objects_sheet"])
RAW = config["raw_dir"]
SETS = select_sets(expected_sets(CATALOGUE, config), config["sets"])
# An existing capture tree must hold every set used, whole: a missing, misnamed
# or gapped set stops the run here, never a smaller benchmark in silence.
TREE = None if config["source"] == "synthetic" else survey_tree(Path(RAW), SETS, config["source"])
if TREE is not None:
    if refusal := TREE.refusal(named=config["sets"] != "all"):
        raise ValueError(refusal)
    if note := TREE.grid_note():
        print(f"note: {note}", file=sys.stderr)
SET_NAMES = [s.name for s in SETS]


wildcard_constraints:
    set=r"[A-Za-z0-9]+_(4inch|8inch)_(3x3|8x8)_(lighton|lightoff)",
    res=r"3x3|8x8",
    protocol=r"clean|paper",
    split="|".join(SPLITS),
    condition=CONDITION_PATTERN,
    model="|".join((*MODELS, LINEAR)),
    task="|".join(TASKS),
    seed=r"\d+",
    object=r"[A-Za-z0-9]+",
    size=r"4inch|8inch",


def raw_set(name):
    return f"{RAW}/{name}{FOLDER_SUFFIX}"


def store(name):
    return f"results/store/{name}.zarr"


def object_arg(name):
    """`--object <sheet row as JSON>` for an object's jobs; nothing for a background.
    Per-set jobs get their own row, not the sheet, so adding a row reruns nothing else."""
    if name in BACKGROUNDS:
        return ""
    return f"--object {shlex.quote(json.dumps(CATALOGUE[name].to_dict(), sort_keys=True))}"


# --- ingest ------------------------------------------------------------------


def raw_source(wildcards):
    if config["source"] == "pickle":
        return f"{RAW}/{wildcards.set}{PICKLE_SUFFIX}"
    return raw_set(wildcards.set)


def ingest_object_arg(wildcards):
    return object_arg(parse_set_name(wildcards.set).object)


# --- rig ---------------------------------------------------------------------


def rig_object_arg(wildcards):
    return object_arg(wildcards.object)


def rig_mesh_files(wildcards):
    spec = CATALOGUE.get(wildcards.object)
    if spec is None or spec.mesh is None:
        return []
    return [spec.mesh.format(size=wildcards.size, inch=wildcards.size.replace("inch", "in"))]


def example_pairs():
    """One object set per resolution (lights on, 8 in and a solid shape where
    captured: the strongest returns) and its NOOBJECT background."""
    picks = {}
    objects = [s for s in SETS if not s.is_background]
    preference = lambda s: (s.light != "lighton", s.size != "8inch", CATALOGUE[s.object].type != "shape", s.name)
    for s in sorted(objects, key=preference):
        picks.setdefault(s.resolution, s)
    return [(store(s.name), store(background_of(s).name)) for s in picks.values()]


def rig_vs_real_pairs():
    """The 3x3 sets of one object (the plain square where captured, else the
    first base shape, else the first base object) at both sizes, lights off
    then on, each with its NOOBJECT background."""
    base = [s for s in SETS if not s.is_background and s.resolution == "3x3" and CATALOGUE[s.object].variant == "base"]
    if not base:
        raise ValueError("rig_vs_real needs 3x3 sets of a base object (config `objects`, `resolutions`)")
    obj = min((s.object for s in base), key=lambda o: (o != "square", CATALOGUE[o].type != "shape", o))
    picks = sorted((s for s in base if s.object == obj), key=lambda s: (s.light != "lightoff", s.size != "8inch"))
    return [(store(s.name), store(background_of(s).name)) for s in picks]


def feature_stats_files():
    """The release's feature statistics that rig_vs_real reads (none unless configured)."""
    folder = config["rig_vs_real"]["feature_stats"]
    return [] if folder is None else [str(Path(folder) / name) for name in (feature_moments.NPZ, feature_moments.JSON)]


def feature_stats_arg():
    folder = config["rig_vs_real"]["feature_stats"]
    return "" if folder is None else f"--feature-stats {shlex.quote(folder)}"


# --- poses -------------------------------------------------------------------


def figure_set():
    """The light-on set whose first tracking frame Fig 12 shows."""
    lit = [s.name for s in SETS if s.light_on]
    if not lit:
        raise ValueError("the pose stage needs at least one light-on capture set (config `lightings`)")
    return lit[0]


def lit_pose_tables():
    return [f"results/poses/{s.name}.parquet" for s in SETS if s.light_on]


def calibration_pose_tables():
    """The light-on background sets' pose tables: the calibration's fixed input."""
    return [f"results/poses/{s.name}.parquet" for s in SETS if s.light_on and s.is_background]


# --- preprocessing -----------------------------------------------------------


def background_store(wildcards):
    return store(background_of(parse_set_name(wildcards.set)).name)


def benchmark_sets(res):
    """The benchmark's capture sets at a resolution: base objects, both sizes and lightings."""
    return [s.name for s in SETS if s.resolution == res and not s.is_background and CATALOGUE[s.object].variant == "base"]


# --- training ----------------------------------------------------------------

TRAIN = config["train"]
RUN_DIR = "results/runs/{protocol}/{res}/{condition}/{split}/{model}_{task}/seed{seed}"


def dataset_files(name, protocol=TRAIN["protocol"]):
    """{x, table}: dataset `name` (`<res>`, or `<variant>_<res>` for a held-out
    variant) as `protocol`'s cells read it (cells.DATASET_DIRS): `clean`'s are
    the preprocessed features' (rules/preprocess.smk, rules/generalisation.smk),
    `paper`'s the raw counts of the capture stores (rules/train.smk)."""
    d = f"results/{DATASET_DIRS[protocol]}"
    return {"x": f"{d}/{name}.zarr", "table": f"{d}/{name}.parquet"}


def run_dirs(models, tasks, splits, res=TRAIN["resolution"]):
    """Benchmark cells (condition `all`) of the configured protocol and
    seeds at `res` (default: the tables' resolution); ill-posed (split,
    task) pairs are never trained (tables report them as n/a)."""
    return [
        RUN_DIR.format(protocol=TRAIN["protocol"], res=res, condition=ALL, split=sp, model=m, task=t, seed=seed)
        for m in models for t in tasks for sp in splits for seed in TRAIN["seeds"]
        if not is_ill_posed(sp, t)
    ]  # fmt: skip


def run_files(models, tasks, splits, name="metrics.json", res=TRAIN["resolution"]):
    return [f"{d}/{name}" for d in run_dirs(models, tasks, splits, res)]


def planned_locations():
    """The gantry locations of every capture set: the rig's, a release tree's,
    or the whole grid for capture streams (read only by ingest)."""
    if config["source"] == "synthetic":
        return select_locations(config["rig"]["n_locations"])
    # a release tree's sets all hold its locations (checked above)
    return sorted(TREE.locations) if TREE.files else range(N_LOCATIONS)


@functools.cache
def planned_samples(res):
    """The dataset's sample table at `res` as the config plans it: one row
    per benchmark set and gantry location (the rig's locations, a release
    tree's, or the whole grid for capture streams), the columns conditions.py
    filters on."""
    locations = planned_locations()
    names = set(benchmark_sets(res))
    rows = [
        {"class": CATALOGUE[s.object].cls, "type": CATALOGUE[s.object].type, "size": s.size, "light": s.light, "location": k}
        for s in SETS if s.name in names for k in locations
    ]  # fmt: skip
    return pd.DataFrame(rows, columns=["class", "type", "size", "light", "location"])


def condition_metrics(task, conditions, resolutions, seeds):
    """metrics.json of the random-split benchmark-model cells of `task` under each
    condition, resolution and seed, leaving out those the condition leaves
    ill-posed on the planned samples (tables report them as n/a)."""
    return [
        f"{RUN_DIR.format(protocol=TRAIN['protocol'], res=res, condition=c, split='random', model=BENCHMARK_MODEL, task=task, seed=seed)}/metrics.json"
        for res in resolutions for c in conditions for seed in seeds
        if ill_posed(planned_samples(res), task, c) is None
    ]  # fmt: skip


def condition_table_metrics(wildcards):
    """Table 7, 8 or 9's cells: its task under its baseline and its
    conditions of `conditions.groups`, at every `conditions.resolutions`."""
    task, conditions = table_conditions(wildcards.table, config["conditions"]["groups"])
    files = condition_metrics(task, conditions, config["conditions"]["resolutions"], config["conditions"]["seeds"])
    if not files:
        raise ValueError(f"{wildcards.table}: every condition leaves {task} ill-posed on the configured sets (config `objects`, `sizes`, `lightings`)")
    return files


def jitter_metrics(wildcards):
    """The jitter sweep's cells: every task at every `jitter.fwhm_ps`."""
    conditions = [jitter_condition(f) for f in config["jitter"]["fwhm_ps"]]
    files = [f for task in TASKS for f in condition_metrics(task, conditions, [JITTER_RESOLUTION], config["jitter"]["seeds"])]
    if not files:
        raise ValueError(f"the jitter sweep needs {JITTER_RESOLUTION} light-on base-object capture sets (config `resolutions`, `lightings`, `objects`)")
    return files


def run_cells():
    """metrics.json of every training cell that the whole workflow trains, for
    the stability report: Tables 2, 5 and 10's and the speed chart's (with
    the linear model), Figs 13-14's at each resolution, Tables 7-9's and the
    jitter sweep's."""
    files = run_files([*TRAINED_MODELS, LINEAR], TASKS, ["random"]) + run_files([BENCHMARK_MODEL], TASKS, SPLITS)
    files += [f for res in TSNE_RESOLUTION.values() for f in run_files([BENCHMARK_MODEL], ["shape"], ["random"], res=res)]
    files += [f for table in CONDITION_TABLES for f in condition_table_metrics(SimpleNamespace(table=table))]
    return sorted(set(files + jitter_metrics(None)))


def cell_arg(wildcards):
    cell = {k: wildcards[k] for k in ("model", "task", "split", "condition", "protocol")}
    cell.update(resolution=wildcards.res, seed=int(wildcards.seed))
    return shlex.quote(json.dumps(cell, sort_keys=True))


def hyper_arg(wildcards):
    if wildcards.model == LINEAR:
        return shlex.quote("{}")
    hp = dict(MODELS[wildcards.model][wildcards.task])
    if TRAIN["max_epochs"] is not None:
        hp["epochs"] = min(hp["epochs"], TRAIN["max_epochs"])
    return shlex.quote(json.dumps(hp, sort_keys=True))


def factory_arg(wildcards):
    if wildcards.model == LINEAR:
        return ""
    return f"--factory {shlex.quote(MODELS[wildcards.model]['factory'])}"


def release_weights_input(wildcards):
    """The release's weights folder (rule release_weights) for a cell whose settings start it from a release checkpoint (`init`)."""
    if wildcards.model == LINEAR or "init" not in MODELS[wildcards.model][wildcards.task]:
        return []
    return ["results/release_weights"]


def budget_arg(wildcards):
    budget = TRAIN["budget_seconds"]
    return "" if budget is None or wildcards.model == LINEAR else f"--budget-seconds {budget}"


def cell_time_axis_arg(wildcards):
    # a jitter cell's blur alone reads the time axis: a new axis retrains no other cell
    return TIME_AXIS_ARG if jitter_fwhm(wildcards.condition) is not None else ""


# --- sim-to-real fit ----------------------------------------------------------

FIT = config["fit"]


def fit_sets():
    """The 3x3 light-on base-object capture sets: the real side of the pairs.
    Drawn when a fit rule is needed, so a config without them fails only then."""
    sets = [s for s in SETS if s.name in benchmark_sets("3x3") and s.light_on]
    if not sets:
        raise ValueError("the sim-to-real fit needs 3x3 light-on base-object capture sets (config `resolutions`, `lightings`, `objects`)")
    return sets


def fit_inputs(wildcards):
    sets = fit_sets()
    return {
        "features": [f"results/features/{s.name}.zarr" for s in sets],
        "twins": sorted({f"results/twin_calibrated/{s.object}_{s.size}.zarr" for s in sets}),
    }


def calibration_inputs(wildcards):
    """The twin calibration's captures (the fit's) and their objects' meshes."""
    sets = fit_sets()
    meshes = sorted({f for s in sets for f in rig_mesh_files(SimpleNamespace(object=s.object, size=s.size))})
    return {"features": [f"results/features/{s.name}.zarr" for s in sets], "meshes": meshes}


# The fit's settings alone, so that a Fig 9 setting (fig9.smk) reruns no fit.
FIT_JOB_CONFIG = json.dumps({"seed": config["seed"], "fit": {k: FIT[k] for k in ("test_fraction", "mode_validation_fraction", "bootstrap")}}, sort_keys=True)


# --- Figs 10 and 11: the held-out variants (rules/generalisation.smk) ---------

HELD_OUT = [v for v in VARIANTS if v != "base"]
# Per figure: the variant it scores on and the tasks it scores (the paper's).
GENERALISATION = {"fig10": ("nonrr", ["location", "shape", "size"]), "fig11": ("italic", ["location", "shape"])}
# `denali evaluate`'s output: one cell (RUN_DIR's fields) scored on one dataset.
EVALUATION = f"{RUN_DIR.replace('results/runs/', 'results/evaluations/{dataset}/')}.json"


def variant_sets(variant, res):
    """The capture sets of one variant's objects at a resolution (both sizes
    and lightings). Drawn when a rule needs them, so a config without them
    fails only then."""
    sets = [s.name for s in SETS if s.resolution == res and not s.is_background and CATALOGUE[s.object].variant == variant]
    if not sets:
        raise ValueError(f"no {variant} capture sets at {res}: Figs 10/11 need them (config `objects`, `resolutions`)")
    return sets


def generalisation_inputs(figure):
    """The cells a figure scores (metrics.json), their evaluations on its
    variant's dataset at the tables' resolution, and that dataset."""
    variant, tasks = GENERALISATION[figure]
    res = TRAIN["resolution"]
    dataset = f"{variant}_{res}"
    files = dataset_files(dataset)
    return {
        "cells": run_files([BENCHMARK_MODEL], tasks, ["random"]),
        "evaluations": [d.replace("results/runs/", f"results/evaluations/{dataset}/") + ".json" for d in run_dirs([BENCHMARK_MODEL], tasks, ["random"])],
        "variant_x": files["x"],
        "variant_table": files["table"],
    }


def paper_dataset_sets(dataset):
    """(capture sets, variant) of a `paper` dataset: `<res>` is the benchmark's
    base-object sets, `<variant>_<res>` a held-out variant's."""
    variant, _, res = dataset.rpartition("_")
    return (variant_sets(variant, res), variant) if variant else (benchmark_sets(res), "base")


# Fig 9 trains the paper's 1D CNN (on the centre zone: experiments/fig9.py)
# whatever train.benchmark_model says; its optimiser settings are
# train.models.cnn1d's location ones, its epochs Fig 9's own.
FIG9_MODEL = "cnn1d"


def fig9_hyper(wildcards):
    if FIG9_MODEL not in MODELS:
        raise ValueError(f"Fig 9 trains the 1D CNN with the settings of train.models.{FIG9_MODEL}, which the config leaves out")
    return json.dumps({**MODELS[FIG9_MODEL]["location"], "epochs": FIT["fig9"]["epochs"]}, sort_keys=True)


# --- cluster requests ---------------------------------------------------------
# Each heavy job asks for its rule's measured cost (config/costs.yaml) at this
# config's scale: runtime (minutes) and mem_mb as `resources:` callables, which
# profiles/slurm passes to sbatch (docs/cluster.md).

CLUSTER = config["cluster"]
COSTS = load_costs(CLUSTER["costs"])
# a release tree's frames are the cameras' own size (the synthetic rig's follow rig.frames)
FRAME_PIXELS = frame_pixels(config["rig"]["frames"] if config["source"] == "synthetic" else {"tracking_scale": 1.0, "colocated_scale": 1.0})


def capture_set_work(name):
    """One capture set's work terms (denali_pipe.workflow.costs) at this config's scale
    (rig.repeats histograms a location: a release holds 3, as the rig's default)."""
    resolution = parse_set_name(name).resolution
    return set_work(len(planned_locations()), config["rig"]["repeats"], resolution, *FRAME_PIXELS)


def job_work(rule_name, wildcards):
    """The work of a rig job (its object, size and resolution: every
    lighting), a per-set job, or a training cell (an upper bound: the whole
    dataset, not its training split, times the cell's epochs)."""
    if rule_name == "rig":
        return combine([capture_set_work(f"{wildcards.object}_{wildcards.size}_{wildcards.res}_{li}") for li in config["lightings"]])
    if rule_name != "train":
        return capture_set_work(wildcards.set)
    samples = len(planned_samples(wildcards.res)) * config["rig"]["repeats"]
    epochs = json.loads(shlex.split(hyper_arg(wildcards))[0]).get("epochs", 1)
    work = training_work(samples * epochs)
    work["hist"] = float(samples * RESOLUTIONS[wildcards.res] ** 2 * N_BINS)
    return work


def request_gpus(wildcards):
    """A training cell's GPUs: train.gpus where its model uses a GPU (`cells.uses_gpu`)."""
    return TRAIN["gpus"] if uses_gpu(wildcards.model) else 0


def request_runtime(rule_name):
    """`runtime` (minutes) of a rule's jobs: predicted CPU seconds x headroom,
    over a training cell's measured GPU speed-up when it asks for GPUs."""
    return lambda wildcards: runtime_minutes(
        predict(cost_model(COSTS, rule_name, wildcards.get("model"), wildcards.get("task"))["cpu_s"], job_work(rule_name, wildcards)),
        CLUSTER,
        gpu_speedup(CLUSTER["gpu_speedup"], rule_name, wildcards.get("model"), wildcards.get("task"), request_gpus(wildcards) if rule_name == "train" else 0),
    )


def request_mem_mb(rule_name):
    """`mem_mb` of a rule's jobs: predicted peak RSS x headroom."""
    return lambda wildcards: mem_mb(
        predict(cost_model(COSTS, rule_name, wildcards.get("model"), wildcards.get("task"))["rss_mb"], job_work(rule_name, wildcards)), CLUSTER
    )
