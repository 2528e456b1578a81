from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).resolve().parents[1]
ASSETS = REPO.parent / "shared" / "denali-assets"
# The release's own benchmark code (MIT): tests compare against it; the project never imports it.
REFERENCE = REPO.parent / "shared" / "reference" / "benchmark"


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


# The end-to-end files run whole DAGs for minutes; under `pytest -n` (the
# Makefile's `make test`) each file runs on one worker in collection order, so
# collecting them first, longest first, starts them together and lets the
# short unit tests fill the gaps instead of queueing the longest run last.
# The SLURM run is second: most of its wall time is waiting on the cluster's
# status checks, which the other worker's tests fill.
E2E_FIRST = ("test_workflow_tiny.py", "test_workflow_slurm.py", "test_faults.py", "test_workflow_sources.py", "test_workflow_dags.py")


def pytest_collection_modifyitems(items):
    rank = {name: i for i, name in enumerate(E2E_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))
