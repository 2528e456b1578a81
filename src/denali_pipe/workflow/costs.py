"""A job's CPU time and peak memory from the measured per-rule cost models.

The cost table (`config/costs.yaml`, fitted by `scripts/bench_stages.py` from
the Snakemake `benchmark:` files of measured runs) gives, per rule, a linear
model of CPU seconds and of peak resident memory (MB) in the work a job does:

- `const`: 1 (interpreter start, imports, fixed set-up)
- `hist`: histogram values the job handles (captures x zones x time bins)
- `frames`: RealSense pixels it handles (locations x (tracking + co-located
  pixels), each an RGB and a depth image)
- `tracking`: tracking-camera pixels it handles (locations x tracking pixels)
- `frame`: the pixels of one location's frame pair (tracking + co-located):
  the stages hold a location's frames at a time, so their memory follows it
- `samples`: training samples it processes (training samples x epochs)

The SLURM profile's requests (rules: `resources:`) and the paper preset's
projection (`scripts/bench_stages.py`) both come from here.
"""

from __future__ import annotations

import math
from pathlib import Path

import yaml

from denali_pipe.core import geometry as geo

TERMS = ("const", "hist", "frames", "tracking", "frame", "samples")


def frame_pixels(frames: dict) -> tuple[int, int]:
    """Pixels of one tracking and one co-located image at the rig's `frames`
    scales (config `rig.frames`), as the rig writes them."""
    tracking = geo.TRACKING_CAMERA.scaled(frames["tracking_scale"]).intrinsics
    colocated = geo.COLOCATED_CAMERA.scaled(frames["colocated_scale"]).intrinsics
    return tracking.width * tracking.height, colocated.width * colocated.height


def set_work(locations: int, repeats: int, resolution: str, tracking_px: int, colocated_px: int) -> dict[str, float]:
    """The work terms of one capture set: `locations` gantry locations of
    `repeats` histograms each at `resolution` ('3x3' or '8x8'), one tracking
    and one co-located frame pair per location of the given pixel counts."""
    zones = geo.RESOLUTIONS[resolution] ** 2
    return {
        "const": 1.0,
        "hist": float(locations * repeats * zones * geo.N_BINS),
        "frames": float(locations * (tracking_px + colocated_px)),
        "tracking": float(locations * tracking_px),
        "frame": float(tracking_px + colocated_px),
        "samples": 0.0,
    }


def combine(works: list[dict[str, float]]) -> dict[str, float]:
    """The work of one job that handles several sets one after another (a
    rig job): terms add, but `const` stays 1 and `frame` is the largest set's."""
    total = {t: sum(w[t] for w in works) for t in TERMS}
    total.update(const=1.0, frame=max(w["frame"] for w in works))
    return total


def training_work(samples: float) -> dict[str, float]:
    """The work terms of a training cell that processes `samples` training
    samples (training split size x epochs)."""
    return {"const": 1.0, "hist": 0.0, "frames": 0.0, "tracking": 0.0, "frame": 0.0, "samples": float(samples)}


def predict(model: dict[str, float], work: dict[str, float]) -> float:
    """A linear cost model's value: sum of coefficient x work term (absent terms 0)."""
    return sum(coef * work[term] for term, coef in model.items())


def load_costs(path: str | Path) -> dict:
    """The cost table; ValueError naming the file and the flaw when malformed."""
    path = Path(path)
    table = yaml.safe_load(path.read_text())
    if not isinstance(table, dict) or not isinstance(table.get("rules"), dict):
        raise ValueError(f"{path}: a cost table needs `rules` (per rule: cpu_s and rss_mb models)")
    for rule, entry in table["rules"].items():
        models = entry.values() if rule == "train" else [entry]
        for m in models:
            for kind in ("cpu_s", "rss_mb"):
                if not isinstance(m.get(kind), dict) or set(m[kind]) - set(TERMS):
                    raise ValueError(f"{path}: rule {rule}: `{kind}` must map terms of {TERMS} to coefficients")
    return table


def cost_model(table: dict, rule: str, model: str | None = None, task: str | None = None) -> dict:
    """The rule's entry; a training cell's: its network and task's
    (`<model>_<task>`), else its network's, else the table's `default` (for
    networks never measured)."""
    entry = table["rules"][rule]
    if rule != "train":
        return entry
    return by_cell(entry, model, task)


def by_cell(entries: dict, model: str | None, task: str | None):
    """A training cell's value in a table keyed `<model>_<task>`, `<model>`
    or `default`, the most specific first."""
    return entries.get(f"{model}_{task}") or entries.get(model) or entries["default"]


def gpu_speedup(speedups: dict[str, float], rule: str, model: str | None = None, task: str | None = None, gpus: int = 0) -> float:
    """How many times faster than one CPU core a job runs: a training cell
    with `gpus` > 0 at its measured speed-up (config `cluster.gpu_speedup`,
    keyed as the cost table), anything else 1."""
    return float(by_cell(speedups, model, task)) if rule == "train" and gpus > 0 else 1.0


def runtime_minutes(cpu_s: float, requests: dict, speedup: float = 1.0) -> int:
    """SLURM runtime (minutes) for a job predicted to need `cpu_s` CPU
    seconds, run `speedup` times faster (a GPU): the prediction times the
    runtime headroom, at least the floor (`requests`: config `cluster`)."""
    return max(requests["min_runtime_min"], math.ceil(cpu_s / speedup * requests["runtime_headroom"] / 60))


def mem_mb(rss_mb: float, requests: dict) -> int:
    """SLURM memory (MB) for a job predicted to peak at `rss_mb`: times the
    memory headroom, at least the floor (`requests`: config `cluster`)."""
    return max(requests["min_mem_mb"], math.ceil(rss_mb * requests["mem_headroom"]))
