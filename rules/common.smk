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
