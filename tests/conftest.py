import importlib
import sys
from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).resolve().parents[1]
ASSETS = REPO.parent / "shared" / "denali-assets"
# The release's own benchmark code (MIT): tests compare against it; the project never imports it.
REFERENCE = REPO.parent / "shared" / "reference" / "benchmark"


def reference_module(module: str):
    """A module of the release's own benchmark code (`../shared/reference`), imported without leaving it on the path."""
    sys.path.insert(0, str(REFERENCE))
    try:
        return importlib.import_module(module)
    finally:
        sys.path.remove(str(REFERENCE))


@pytest.fixture(scope="session")
def catalogue():
    """The objects sheet's specs ({name: ObjectSpec}, frozen)."""
    from denali_pipe.core.objects import load_catalogue

    return load_catalogue(REPO / "config" / "objects.tsv")


@pytest.fixture(scope="session")
def demo_config() -> dict:
    """The default (demo) config as Snakemake sees it after validation."""
    with open(REPO / "config" / "config.yaml") as f:
        return yaml.safe_load(f)


@pytest.fixture(scope="session")
def time_axis(demo_config):
    """The configured time axis of the histograms (config `sensor.time_axis`)."""
    from denali_pipe.core.geometry import TimeAxis

    return TimeAxis.from_config(demo_config["sensor"]["time_axis"])


# The end-to-end files run whole DAGs for minutes; under `pytest -n` (the
# Makefile's `make test`, with --no-loadscope-reorder) each file runs on one
# worker in collection order, two queued per worker from the start. So the
# tiny rule all (~8 min within the suite) and the SLURM run (~4 min, mostly
# waiting on the cluster's status checks, which the other worker's tests
# fill) start at once, the tiny run's worker queues the short DAG builds and
# the SLURM run's the sources and fault runs; the unit tests fill the rest.
E2E_FIRST = ("test_workflow_tiny.py", "test_workflow_slurm.py", "test_workflow_dags.py", "test_workflow_sources.py", "test_faults.py")


def pytest_collection_modifyitems(items):
    rank = {name: i for i, name in enumerate(E2E_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))
