from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).resolve().parents[1]
ASSETS = REPO.parent / "shared" / "denali-assets"


@pytest.fixture(scope="session")
def demo_config() -> dict:
    """The default (demo) config as Snakemake sees it after validation."""
    with open(REPO / "config" / "config.yaml") as f:
        return yaml.safe_load(f)
