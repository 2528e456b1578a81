# Config loading and validation, capture-set discovery, input functions.
import json
import shlex

from snakemake.utils import min_version, validate

from pathlib import Path

from denali_pipe.capture_sets import FOLDER_SUFFIX, PICKLE_SUFFIX, background_of, expected_sets, parse_set_name
from denali_pipe.objects import BACKGROUNDS, load_catalogue

min_version("9.0")


configfile: "config/config.yaml"


validate(config, "../config/schema.yaml")

CATALOGUE = load_catalogue(config["objects_sheet"])
RAW = config["raw_dir"]
SETS = expected_sets(CATALOGUE, config)
if config["source"] != "synthetic":
    # an existing capture tree holds what was captured: use the configured sets it has
    suffix = FOLDER_SUFFIX if config["source"] == "release" else PICKLE_SUFFIX
    SETS = [s for s in SETS if Path(f"{RAW}/{s.name}{suffix}").exists()]
    if not SETS:
        raise ValueError(f"source {config['source']}: no configured capture set found in {RAW}")
SET_NAMES = [s.name for s in SETS]


wildcard_constraints:
    set=r"[A-Za-z0-9]+_(4inch|8inch)_(3x3|8x8)_(lighton|lightoff)",
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


# --- poses -------------------------------------------------------------------


def figure_set():
    """The light-on set whose first tracking frame Fig 12 shows."""
    lit = [s.name for s in SETS if s.light_on]
    if not lit:
        raise ValueError("the pose stage needs at least one light-on capture set (config `lightings`)")
    return lit[0]
