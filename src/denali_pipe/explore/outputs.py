"""What a results/ folder holds for the explorer, what it lacks, and the
`snakemake` target that builds each missing output.

The paths are the workflow's (rules/*.smk); a target is given relative to
the folder the workflow runs in (the parent of results/), and is run with
the same `--configfile` as the run that wrote the rest.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import pandas as pd

from denali_pipe.core.capture_sets import CaptureSet, parse_set_name
from denali_pipe.core.geometry import RESOLUTIONS
from denali_pipe.train.cells import ALL, DATASET_DIRS, PROTOCOLS, TASKS, is_ill_posed
from denali_pipe.train.saved_cell import MODEL_FILE

ZARR = ".zarr"
STORES = "store"
FEATURES = "features"
TWINS = "twin_calibrated"  # the twins the transforms were fitted on
RUNS = "runs"
INDEX = "index"
POSITIONS = "calibration/tag1_positions.parquet"
SCENE = "calibration/scene.json"
TRANSFORMS = "transforms.json"
# The aggregate targets that build every output of a kind.
ALL_STORES = "index/captures.parquet"
BENCHMARK_CELLS = "table5.csv"


def target(rel: str) -> str:
    """The command that builds results/<rel>."""
    return f"snakemake --cores all results/{rel}"


def dataset_paths(res: str, protocol: str = PROTOCOLS[0]) -> tuple[str, str]:
    """(input array, sample table) of the benchmark dataset at a resolution that
    `protocol`'s cells train on (features under clean, raw counts under paper), relative to results/."""
    d = DATASET_DIRS[protocol]
    return f"{d}/{res}{ZARR}", f"{d}/{res}.parquet"


def crop_path(res: str) -> str:
    return f"{FEATURES}/crop_{res}.json"


def features_path(set_name: str) -> str:
    return f"{FEATURES}/{set_name}{ZARR}"


def store_path(set_name: str) -> str:
    return f"{STORES}/{set_name}{ZARR}"


def twin_path(obj: str, size: str) -> str:
    return f"{TWINS}/{obj}_{size}{ZARR}"


def index_path(set_name: str) -> str:
    return f"{INDEX}/{set_name}.parquet"


@dataclass(frozen=True, order=True)
class CellChoice:
    """A benchmark training cell (condition `all`: trained on every sample)
    but for its task: the explorer predicts with the location, shape and
    size cells of one choice."""

    protocol: str
    resolution: str
    split: str
    model: str
    seed: int

    def run_path(self, task: str) -> str:
        """The run folder of this choice's `task` cell, relative to results/ (rules/common.smk's RUN_DIR)."""
        return f"{RUNS}/{self.protocol}/{self.resolution}/{ALL}/{self.split}/{self.model}_{task}/seed{self.seed}"


@dataclass(frozen=True)
class Missing:
    """An output the explorer would show, absent: what it is and the command that builds it."""

    what: str
    command: str


@dataclass(frozen=True)
class Inventory:
    """What results/ holds (only complete outputs: a store or a cell that
    is still being written has no final name yet)."""

    root: Path
    sets: tuple[CaptureSet, ...]  # capture stores, by name
    features: frozenset[str]  # set names with a features store
    twins: frozenset[tuple[str, str]]  # (object, size)
    datasets: frozenset[tuple[str, str]]  # (protocol, resolution) with both dataset files
    cells: frozenset[tuple[CellChoice, str]]  # (choice, task) with a saved model
    calibrated: bool  # tag-1 positions and scene.json
    transforms: bool

    def path(self, rel: str) -> Path:
        return self.root / rel

    def has_set(self, cs: CaptureSet) -> bool:
        return cs in self.sets

    def choices(self, resolution: str) -> list[CellChoice]:
        """Every cell choice at a resolution with at least one task's model saved."""
        return sorted({c for c, _ in self.cells if c.resolution == resolution})

    def cell_status(self, choice: CellChoice, task: str) -> Missing | None:
        """None when the cell's model is saved; else why not and how to build it."""
        if (choice, task) in self.cells:
            return None
        run = choice.run_path(task)
        if is_ill_posed(choice.split, task):
            return Missing(f"no {task} cell under the {choice.split} split: its test {task}s never occur in training (not trained)", "")
        return Missing(f"no {task} cell {run}", target(f"{run}/metrics.json"))

    def missing(self) -> list[Missing]:
        """The kinds of output the explorer reads that are absent altogether
        (or, for datasets, twins and features, absent for some captured sets)."""
        out = []
        if not self.sets:
            out.append(Missing(f"no capture stores ({STORES}/)", target(ALL_STORES)))
        if not self.calibrated:
            out.append(Missing("no calibration (tag-1 positions and tracking camera)", target(POSITIONS)))
        objects = [s for s in self.sets if not s.is_background]
        for res in sorted({s.resolution for s in objects} - {r for _, r in self.datasets}):
            out.append(Missing(f"no {res} benchmark dataset (per-location test error)", target(dataset_paths(res)[0])))
        no_features = sorted(s.name for s in objects if s.name not in self.features)
        if no_features:
            out.append(
                Missing(f"no features for {len(no_features)} of {len(objects)} object sets, e.g. {no_features[0]}", target(features_path(no_features[0])))
            )
        no_twin = sorted({(s.object, s.size) for s in objects} - self.twins)
        if no_twin:
            out.append(Missing(f"no digital twin for {len(no_twin)} object sizes, e.g. {' '.join(no_twin[0])}", target(twin_path(*no_twin[0]))))
        if not self.transforms:
            out.append(Missing("no sim-to-real transforms", target(TRANSFORMS)))
        if not self.cells:
            out.append(Missing(f"no training cells ({RUNS}/)", target(BENCHMARK_CELLS)))
        return out


def _zarr_names(folder: Path) -> list[str]:
    return sorted(p.name.removesuffix(ZARR) for p in folder.glob(f"*{ZARR}") if p.is_dir()) if folder.is_dir() else []


def _cells(runs: Path) -> frozenset[tuple[CellChoice, str]]:
    """Every saved benchmark model under runs/<protocol>/<res>/all/<split>/<model>_<task>/seed<N>/."""
    found = set()
    for model_file in runs.glob(f"*/*/{ALL}/*/*_*/seed*/{MODEL_FILE}"):
        seed_dir = model_file.parent
        model, _, task = seed_dir.parent.name.rpartition("_")
        split, res, protocol = seed_dir.parent.parent.name, seed_dir.parents[3].name, seed_dir.parents[4].name
        if task in TASKS and seed_dir.name.removeprefix("seed").isdigit():
            found.add((CellChoice(protocol, res, split, model, int(seed_dir.name.removeprefix("seed"))), task))
    return frozenset(found)


def scan(root: Path) -> Inventory:
    """The inventory of a results folder (an absent folder holds nothing)."""
    root = Path(root)
    sets = []
    for name in _zarr_names(root / STORES):
        try:
            sets.append(parse_set_name(name))
        except ValueError:
            continue  # not a capture store of the workflow's naming: not ours to show
    datasets = frozenset((p, res) for p in PROTOCOLS for res in RESOLUTIONS if all((root / f).exists() for f in dataset_paths(res, p)))
    twins = set()
    for name in _zarr_names(root / TWINS):
        obj, _, size = name.rpartition("_")
        twins.add((obj, size))
    return Inventory(
        root=root,
        sets=tuple(sorted(sets, key=lambda s: s.name)),
        features=frozenset(_zarr_names(root / FEATURES)),
        twins=frozenset(twins),
        datasets=datasets,
        cells=_cells(root / RUNS),
        calibrated=(root / POSITIONS).is_file() and (root / SCENE).is_file(),
        transforms=(root / TRANSFORMS).is_file(),
    )


@lru_cache(maxsize=8)
def _dataset_objects(table: Path, mtime_ns: int) -> frozenset[str]:
    return frozenset(pd.read_parquet(table, columns=["object"])["object"])


def benchmark_objects(inv: Inventory) -> frozenset[str] | None:
    """The objects of the benchmark datasets (the catalogue's base objects:
    the dataset takes no other), or None when no dataset says."""
    tables = [inv.path(dataset_paths(res, p)[1]) for p, res in sorted(inv.datasets)]
    if not tables:
        return None
    return frozenset().union(*(_dataset_objects(t, t.stat().st_mtime_ns) for t in tables))
