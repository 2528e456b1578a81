# Config loading and validation, capture-set discovery, input functions.
import json
import shlex

from snakemake.utils import min_version, validate

from denali_pipe.capture_sets import FOLDER_SUFFIX, background_of, expected_sets
from denali_pipe.objects import BACKGROUNDS, load_catalogue

min_version("9.0")


configfile: "config/config.yaml"


validate(config, "../config/schema.yaml")

CATALOGUE = load_catalogue(config["objects_sheet"])
SETS = expected_sets(CATALOGUE, config)
RAW = config["raw_dir"]


wildcard_constraints:
    object=r"[A-Za-z0-9]+",
    size=r"4inch|8inch",


def raw_set(name):
    return f"{RAW}/{name}{FOLDER_SUFFIX}"


def raw_sets():
    return [raw_set(s.name) for s in SETS]


# --- rig ---------------------------------------------------------------------


def rig_object_arg(wildcards):
    if wildcards.object in BACKGROUNDS:
        return ""
    return f"--object {shlex.quote(json.dumps(CATALOGUE[wildcards.object].to_dict(), sort_keys=True))}"


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
    return [(raw_set(s.name), raw_set(background_of(s).name)) for s in picks.values()]
