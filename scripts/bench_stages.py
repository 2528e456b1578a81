#!/usr/bin/env python
"""Stage throughput and the paper preset's projection; prints figures, asserts nothing.

    python scripts/bench_stages.py run -- SNAKEMAKE_ARGS...
    python scripts/bench_stages.py fit RUN [RUN ...] [--coarse RUN ...] [--check RUN]
                                   [--write-costs config/costs.yaml] [--nodes 4 --node-cores 16 ...]
    python scripts/bench_stages.py project RUN [--nodes 4 ...]

`run` is Snakemake with every benchmarked job sampled every 0.5 s (see
`run_snakemake`); make measured runs with it. `fit` reads the Snakemake
`benchmark:` files of one or more finished runs (each a workflow folder:
benchmarks/, results/, data/raw/) and, per stage (rule):

- prints CPU seconds per job, captures (or training samples) per CPU-second,
  MB read and written per CPU-second and peak memory at each run's scale;
- fits a per-job cost model, CPU seconds and peak MB linear in the job's work
  (`denali_pipe.workflow.costs`: histogram values, frame pixels, training samples),
  on every run given; `--coarse` names runs made by plain `snakemake`, whose
  CPU times are extrapolated (see `full_cpu`);
- with `--check RUN`: fits on the other runs and compares RUN's measured
  CPU seconds per stage with the projection at RUN's own scale;
- projects the paper preset (`config/presets/paper.yaml`, every table and
  figure): per-job costs on its dry-run DAG, the DAG's critical path and list
  schedules on 2 and 16 cores and on a SLURM cluster (training cells on GPUs
  at their measured speed-up, config `cluster.gpu_speedup`, each submission
  paying a measured overhead);
- with `--write-costs`: writes the fitted models as the cost table the
  rules' SLURM requests come from.

`project` makes the projection alone, from the committed cost table
(`cluster.costs`) instead of a fit; RUN (any finished run, `--coarse` style)
gives only each split's share of its dataset and the cells' input sizes.

CPU time, not wall time, is the measure throughout: the machines measured on
were shared, and contention stretches wall time far more than CPU time.
"""

from __future__ import annotations

import argparse
import heapq
import json
import re
import subprocess
import sys
import tempfile
from collections import defaultdict
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import yaml
from scipy.optimize import nnls

from denali_pipe.cli import warm_start
from denali_pipe.core.capture_sets import FOLDER_SUFFIX, parse_set_name
from denali_pipe.train.cells import uses_gpu
from denali_pipe.workflow import costs

REPO = Path(__file__).resolve().parents[1]
WORKFLOW_FILES = ("Snakefile", "rules", "config", "profiles", "envs", "report", "examples")
# The stages fitted, and the work terms their CPU time and peak memory are
# linear in: CPU time in what each reads or writes; peak memory in one
# location's frames (the capture stages stream locations), a set's histograms
# (preprocess) or a cell's whole dataset, as input values in its `hist` term.
CPU_TERMS = {
    "rig": ("const", "hist", "frames"),
    "ingest": ("const", "hist", "frames"),
    "poses": ("const", "tracking"),
    "preprocess": ("const", "hist"),
    "train": ("const", "samples"),
}
RSS_TERMS = {
    "rig": ("const", "frame"),
    "ingest": ("const", "frame"),
    "poses": ("const", "frame"),
    "preprocess": ("const", "hist"),
    "train": ("const", "hist"),
}
# Snakemake's benchmark sampling (snakemake/benchmark.py): every 0.5 s up to
# the 31st sample, then every 30 s; a job's record is its last sample.
SHORT_SAMPLES_S = 15.0
LONG_INTERVAL_S = 30.0


def run_snakemake(args: list[str]) -> None:
    """Snakemake's CLI with every job's resources sampled every 0.5 s.

    Snakemake samples a benchmarked job every 0.5 s for its first 15 s, then
    every 30 s, and keeps the last sample: a job of 16-45 s loses everything
    after its 15th second (the demo's 43-s training cells read ~15 CPU-s).
    Local jobs are sampled in this process's threads, so the default
    interval patched here applies to all of them.

    Every job starts afresh (no warm start): a warm job's work runs in the
    server's fork, outside the process tree its benchmark samples.
    """
    from snakemake import benchmark, cli

    measure = benchmark.benchmarked.__wrapped__  # the generator under @contextmanager
    pid, record, _ = measure.__defaults__
    measure.__defaults__ = (pid, record, benchmark.BENCHMARK_INTERVAL_SHORT)
    warm_start.start = lambda enabled, log: None
    sys.argv = ["snakemake", *args]
    cli.main()


def full_cpu(wall_s: float, cpu_s: float) -> float:
    """A coarse-sampled job's CPU seconds, extrapolated from its last sample
    (at 15 s, 45 s, 75 s, ...) to its end at the CPU rate it had until then."""
    if wall_s <= SHORT_SAMPLES_S:
        return cpu_s
    last = SHORT_SAMPLES_S + LONG_INTERVAL_S * ((wall_s - SHORT_SAMPLES_S) // LONG_INTERVAL_S)
    return cpu_s * wall_s / last


# --- a measured run ---------------------------------------------------------------


def run_scale(run: Path) -> dict:
    """Locations, repeats and frame pixels of a run, from one of its stores."""
    store = next((run / "results/store").glob("*.zarr"))
    shape = {a: json.loads((store / a / "zarr.json").read_text())["shape"] for a in ("histogram", "tracking_rgb", "colocated_rgb")}
    return {
        "locations": shape["histogram"][0],
        "repeats": shape["histogram"][1],
        "tracking_px": shape["tracking_rgb"][1] * shape["tracking_rgb"][2],
        "colocated_px": shape["colocated_rgb"][1] * shape["colocated_rgb"][2],
    }


def capture_work(scale: dict, set_name: str) -> dict[str, float]:
    res = parse_set_name(set_name).resolution
    return costs.set_work(scale["locations"], scale["repeats"], res, scale["tracking_px"], scale["colocated_px"])


def train_row(run: Path, bench: Path) -> dict:
    """A training cell's work and what it measured of itself (metrics.json)."""
    cell_dir = run / bench.relative_to(run / "benchmarks").with_suffix("")
    m = json.loads((cell_dir / "metrics.json").read_text())
    n_data = m["n_train"] + m["n_validation"] + m["n_test"]
    work = costs.training_work(m["samples_seen"] or 0)  # the linear model fits in closed form: no samples seen
    work["hist"] = float(n_data * np.prod(m["input_shape"]))
    dataset = run / f"results/datasets/{m['cell']['resolution']}.parquet"
    return {
        "work": work,
        "model": m["cell"]["model"],
        "task": m["cell"]["task"],
        "units": m["samples_seen"] or 0,
        "key": (m["cell"]["split"], m["cell"]["condition"], m["cell"]["task"]),
        "train_fraction": m["n_train"] / pq.read_metadata(dataset).num_rows,
        "input_values": int(np.prod(m["input_shape"])),
        "flops": m.get("flops") or 0,
        "resolution": m["cell"]["resolution"],
    }


def check_cold(run: Path, bench: Path) -> None:
    """Refuse a job that ran warm (its log, at the benchmark's path under
    logs/, carries the worker's usage line): its benchmark measured the
    client, not the work."""
    job_log = run / "logs" / bench.relative_to(run / "benchmarks").with_suffix(".log")
    if job_log.exists() and warm_start.worker_usage(job_log.read_text(errors="replace")) is not None:
        raise SystemExit(
            f"{bench}: the job ran warm ({job_log} says so), so its benchmark measured only its client;"
            " measure with `bench_stages.py run` or `--config warm_start=False`"
        )


def measured_jobs(run: Path, coarse: bool) -> pd.DataFrame:
    """One row per benchmarked job of the fitted stages: its rule, measured
    CPU seconds, peak MB, MB read + written, work terms, and `units` (the
    captures or training samples it handled)."""
    scale = run_scale(run)
    rows = []
    for bench in sorted((run / "benchmarks").rglob("*.tsv")):
        parts = bench.relative_to(run / "benchmarks").parts
        rule = "train" if parts[0] == "results" else parts[0]
        if rule not in CPU_TERMS:
            continue
        check_cold(run, bench)
        rec = pd.read_csv(bench, sep="\t").iloc[0]
        stretch = full_cpu(rec.s, rec.cpu_time) / rec.cpu_time if coarse and rec.cpu_time > 0 else 1.0
        row = {"run": run.name or str(run), "rule": rule, "job": bench.stem, "wall_s": rec.s, "cpu_s": rec.cpu_time * stretch}
        row.update(rss_mb=rec.max_rss, io_mb=(rec.io_in + rec.io_out) * stretch, model="", task="")
        if rule == "train":
            row.update(train_row(run, bench))
        else:
            if rule == "rig":
                sets = [p.name.removesuffix(FOLDER_SUFFIX) for p in (run / "data/raw").glob(f"{bench.stem}_*{FOLDER_SUFFIX}")]
            else:
                sets = [bench.stem]
            row["work"] = costs.combine([capture_work(scale, s) for s in sets])
            row["units"] = scale["locations"] * scale["repeats"] * len(sets)
        rows.append(row)
    jobs = pd.DataFrame(rows)
    for t in costs.TERMS:
        jobs[t] = [w[t] for w in jobs.work]
    return jobs.drop(columns="work").assign(scale=f"{scale['locations']} loc, {scale['tracking_px'] / 1e6:.2f}+{scale['colocated_px'] / 1e6:.2f} Mpx")


# --- fitting ----------------------------------------------------------------------


def fit_linear(jobs: pd.DataFrame, terms: tuple[str, ...], target: str) -> dict[str, float]:
    """Non-negative least squares of `target` on `terms`, each column scaled
    to unit maximum first; terms the jobs never vary (e.g. frames at one frame
    size next to locations) get the coefficient their data can pin, the rest 0."""
    x = jobs[list(terms)].to_numpy(float)
    norm = np.where(x.max(0) > 0, x.max(0), 1.0)
    coef, _ = nnls(x / norm, jobs[target].to_numpy(float))
    return {t: float(c / n) for t, c, n in zip(terms, coef, norm) if c > 0}


def fit_models(jobs: pd.DataFrame) -> dict:
    """{rule: {cpu_s: model, rss_mb: model}}, training per model name."""
    fitted = {}
    for rule, group in jobs.groupby("rule"):
        if rule == "train":
            cells = fit_cells(group)
            # a network never measured gets the 1D CNN's model (costs.cost_model's `default`)
            fitted[rule] = {**cells, "default": cells["cnn1d"]}
        else:
            fitted[rule] = {"cpu_s": fit_linear(group, CPU_TERMS[rule], "cpu_s"), "rss_mb": fit_linear(group, RSS_TERMS[rule], "rss_mb")}
    return fitted


def fit_cells(cells: pd.DataFrame, reference: str = "cnn1d") -> dict:
    """Per network and task (`<model>_<task>`), and per network pooled
    (`<model>`), CPU seconds linear in samples x epochs. Where the measured
    cells all saw about as many samples (within 1.5x: one scale, one
    schedule) no per-sample cost is pinned: the fixed cost is taken as the
    `reference` network's (same interpreter, imports, data loading) and the
    per-sample cost as the rest of the CPU time per sample, at least the
    network's forward FLOPs times the reference's CPU seconds per FLOP
    (these small networks are compute-bound on a CPU core)."""
    ref = fit_linear(cells[cells.model == reference], CPU_TERMS["train"], "cpu_s")
    per_flop = ref.get("samples", 0.0) / cells[cells.model == reference].flops.mean()
    groups = [*cells.groupby("model"), *cells.groupby(cells.model + "_" + cells.task)]
    fitted = {}
    for key, g in groups:
        cpu = fit_linear(g, CPU_TERMS["train"], "cpu_s")
        if g.samples.max() < 1.5 * g.samples.min() and key != reference:
            fixed = ref.get("const", 0.0)
            cpu = {"const": fixed, "samples": float(max(per_flop * g.flops.mean(), ((g.cpu_s - fixed) / g.samples).mean()))}
        fitted[key] = {"cpu_s": cpu, "rss_mb": fit_linear(g, RSS_TERMS["train"], "rss_mb")}
    return fitted


def predicted(jobs: pd.DataFrame, fitted: dict, kind: str) -> np.ndarray:
    return np.array(
        [costs.predict(costs.cost_model({"rules": fitted}, r.rule, r.model, r.task)[kind], {t: r[t] for t in costs.TERMS}) for _, r in jobs.iterrows()]
    )


# --- printing ---------------------------------------------------------------------


def print_throughput(jobs: pd.DataFrame, fitted: dict) -> None:
    print("Per stage and scale (CPU seconds; units: captures, or samples for training cells):")
    print(f"{'stage':<18}{'scale':<26}{'jobs':>5}{'CPU-s/job':>10}{'units/CPU-s':>12}{'MB/CPU-s':>10}{'peak MB':>9}")
    for (rule, model, scale), g in jobs.groupby(["rule", "model", "scale"]):
        name = f"{rule} {model}".strip()
        print(
            f"{name:<18}{scale:<26}{len(g):>5}{g.cpu_s.mean():>10.1f}{g.units.sum() / g.cpu_s.sum():>12.0f}"
            f"{g.io_mb.sum() / g.cpu_s.sum():>10.1f}{g.rss_mb.max():>9.0f}"
        )
    print("\nPer-job cost models (fitted on every run given; CPU-s and MB per unit of work):")
    for rule in fitted:
        for model, m in fitted[rule].items() if rule == "train" else [("", fitted[rule])]:
            terms = {kind: " + ".join(f"{v:.3g} {t}" for t, v in m[kind].items()) or "0" for kind in ("cpu_s", "rss_mb")}
            print(f"  {rule} {model}".rstrip() + f": cpu_s = {terms['cpu_s']};  rss_mb = {terms['rss_mb']}")
    # growth: what one more location of one set adds, at the paper's frames
    tpx, cpx = costs.frame_pixels({"tracking_scale": 1.0, "colocated_scale": 1.0})
    print("\nGrowth at the paper's 1280x720 frames: CPU-s one more location of a set adds to its job; peak MB of a job at 100 locations:")
    for rule in ("rig", "ingest", "poses", "preprocess"):
        if rule in fitted:
            per = {r: costs.predict(fitted[rule]["cpu_s"], {**costs.set_work(1, 3, r, tpx, cpx), "const": 0}) for r in ("3x3", "8x8")}
            peak = costs.predict(fitted[rule]["rss_mb"], costs.set_work(100, 3, "8x8", tpx, cpx))
            print(
                f"  {rule:<11} 3x3 {per['3x3']:.3f}, 8x8 {per['8x8']:.3f} CPU-s a location; fixed {fitted[rule]['cpu_s'].get('const', 0):.1f} CPU-s a job; peak {peak:.0f} MB"
            )
    for model, m in fitted.get("train", {}).items():
        print(
            f"  train {model:<12}{m['cpu_s'].get('samples', 0) * 1e3:.3f} CPU-ms a training sample-epoch; fixed {m['cpu_s'].get('const', 0):.1f} CPU-s a cell"
        )


def print_check(jobs: pd.DataFrame, check: str) -> None:
    """Measured against projected CPU seconds per stage of the run `check`,
    the models fitted without it."""
    rest, mine = jobs[jobs.run != check], jobs[jobs.run == check].copy()
    fitted = fit_models(rest)
    mine = mine[[r.rule in fitted for _, r in mine.iterrows()]]
    mine["proj_cpu"] = predicted(mine, fitted, "cpu_s")
    mine["proj_rss"] = predicted(mine, fitted, "rss_mb")
    print(f"\nMeasured vs projected on {check} (models fitted on the other runs only):")
    print(f"{'stage':<18}{'jobs':>5}{'CPU-s measured':>16}{'projected':>11}{'diff':>7}{'peak MB meas.':>15}{'proj.':>7}")
    for (rule, model), g in mine.groupby(["rule", "model"]):
        diff = g.proj_cpu.sum() / g.cpu_s.sum() - 1
        print(
            f"{(rule + ' ' + model).strip():<18}{len(g):>5}{g.cpu_s.sum():>16.0f}{g.proj_cpu.sum():>11.0f}{diff:>+7.0%}{g.rss_mb.max():>15.0f}{g.proj_rss.max():>7.0f}"
        )
    print(f"{'all':<18}{len(mine):>5}{mine.cpu_s.sum():>16.0f}{mine.proj_cpu.sum():>11.0f}{mine.proj_cpu.sum() / mine.cpu_s.sum() - 1:>+7.0%}")


# --- the paper preset's DAG -------------------------------------------------------


def scratch_snakemake(runs: list[tuple[list[str], dict]]) -> list[str]:
    """stdout of `snakemake ARGS --configfile config/presets/paper.yaml
    extra.yaml` for each (ARGS, extra config), in one scratch copy of the
    workflow without outputs."""
    outs = []
    with tempfile.TemporaryDirectory(prefix="denali-dag-") as wd:
        for name in WORKFLOW_FILES:
            subprocess.run(["cp", "-r", str(REPO / name), wd], check=True)
        snakemake = str(Path(sys.executable).parent / "snakemake")
        for args, extra in runs:
            (Path(wd) / "extra.yaml").write_text(yaml.safe_dump(extra))
            config = ["--configfile", "config/presets/paper.yaml", "extra.yaml"]
            outs.append(subprocess.run([snakemake, *args, *config], cwd=wd, capture_output=True, text=True, check=True).stdout)
    return outs


def paper_dag(dot: str) -> tuple[dict[int, dict], dict[int, list[int]]]:
    """{node: {rule, wildcards}} and {node: its parents} of `snakemake --dag` output."""
    nodes, parents = {}, defaultdict(list)
    for m in re.finditer(r'^\s*(\d+)\[label = "([^"]*)"', dot, re.M):
        rule, *pairs = m[2].split("\\n")
        nodes[int(m[1])] = {"rule": rule, **dict(p.split(": ", 1) for p in pairs)}
    for m in re.finditer(r"^\s*(\d+) -> (\d+)", dot, re.M):
        parents[int(m[2])].append(int(m[1]))
    return nodes, parents


def print_requests(dry_run: str, label: str) -> None:
    """Per rule (training: per model), the range of the runtime, mem_mb and
    gpu requests in a dry run's job listing: what profiles/slurm submits."""
    requests = defaultdict(list)
    for block in re.split(r"^rule ", dry_run, flags=re.M)[1:]:
        rule = block.split(":", 1)[0]
        model = re.search(r"model=([\w-]+)", block)
        res = dict(re.findall(r"(\w+)=([\d.]+)(?=[,\s])", block.split("resources:", 1)[1].splitlines()[0])) if "resources:" in block else {}
        if "runtime" in res:
            requests[f"{rule} {model[1] if model and rule == 'train' else ''}".strip()].append(res)
    print(f"\nSLURM requests on the paper preset ({label}), per rule: runtime (min), mem_mb, gpu (min-max over its jobs)")
    for key, rs in sorted(requests.items()):
        span = {k: f"{min(float(r.get(k, 0)) for r in rs):g}-{max(float(r.get(k, 0)) for r in rs):g}" for k in ("runtime", "mem_mb", "gpu")}
        print(f"  {key:<20}{len(rs):>5} jobs  runtime {span['runtime']:<12} mem_mb {span['mem_mb']:<12} gpu {span['gpu']}")


def paper_config(configfiles: list[str]) -> dict:
    from snakemake.utils import update_config

    cfg = yaml.safe_load((REPO / "config/config.yaml").read_text())
    for path in ["config/presets/paper.yaml", *configfiles]:
        update_config(cfg, yaml.safe_load((REPO / path).read_text()))
    return cfg


def paper_jobs(nodes: dict, parents: dict, cfg: dict, jobs: pd.DataFrame) -> dict[int, dict]:
    """Each DAG node's rule, model and work at the paper preset's scale.
    A pose or preprocess node's set is its object's ingest parent; a training
    cell's resolution its dataset parent's; its training samples are its
    split's measured share of the dataset (the same (split, condition, task)
    measured, else the random split's) times the dataset times its epochs."""
    rig = cfg["rig"]
    tpx, cpx = costs.frame_pixels(rig["frames"])

    def work_of(s):
        return costs.set_work(rig["n_locations"], rig["repeats"], parse_set_name(s).resolution, tpx, cpx)

    cells = jobs[jobs.rule == "train"]
    share = cells.groupby("key").train_fraction.mean().to_dict()
    random_share = cells[[k[0] == "random" for k in cells.key]].train_fraction.mean()
    input_values = cells.groupby("resolution").input_values.first().to_dict()
    out = {}
    for node, n in nodes.items():
        rule, model, task, work = n["rule"], "", "", None
        if rule == "ingest":
            work = work_of(n["set"])
        elif rule == "rig":
            sets = [f"{n['object']}_{n['size']}_{n['res']}_{li}" for li in cfg["lightings"]]
            work = costs.combine([work_of(s) for s in sets])
        elif rule in ("poses", "preprocess"):  # Snakemake's DAG labels leave their set out
            sets = [nodes[p]["set"] for p in parents[node] if nodes[p]["rule"] == "ingest"]
            # a preprocess job's parents: its set's ingest and its background's
            work = work_of(sets[0] if len(sets) == 1 else next(s for s in sets if not parse_set_name(s).is_background))
        elif rule == "train":
            model, task = n["model"], n["task"]
            data = next(p for p in parents[node] if nodes[p]["rule"] in ("dataset", "variant_dataset"))
            res = nodes[data].get("res", cfg["train"]["resolution"])
            n_sets = sum(1 for p in parents[data] if nodes[p]["rule"] == "preprocess")
            dataset = n_sets * rig["n_locations"] * rig["repeats"]
            hyper = cfg["train"]["models"].get(model) or {}
            epochs = hyper.get(n["task"], {}).get("epochs", 0)
            if cfg["train"]["max_epochs"] is not None:
                epochs = min(epochs, cfg["train"]["max_epochs"])
            frac = share.get((n["split"], n["condition"], n["task"]), random_share)
            work = costs.training_work(frac * dataset * epochs)
            work["hist"] = float(dataset * input_values.get(res, input_values["3x3"]) * (64 / 9 if res == "8x8" and "8x8" not in input_values else 1))
        out[node] = {"rule": rule, "model": model, "task": task, "work": work}
    return out


def job_cost(job: dict, fitted: dict, kind: str) -> float | None:
    if job["work"] is None or job["rule"] not in fitted:
        return None
    return max(0.0, costs.predict(costs.cost_model({"rules": fitted}, job["rule"], job["model"], job["task"])[kind], job["work"]))


def bottom_levels(durations: dict[int, float], parents: dict[int, list[int]]) -> dict[int, float]:
    """Longest path from each job to the end of the DAG, its own duration included."""
    children = defaultdict(list)
    for child, ps in parents.items():
        for p in ps:
            children[p].append(child)
    level: dict[int, float] = {}

    def visit(node: int) -> float:
        if node not in level:
            level[node] = durations[node] + max((visit(c) for c in children[node]), default=0.0)
        return level[node]

    for node in durations:
        visit(node)
    return level


def list_schedule(durations: dict[int, float], parents: dict[int, list[int]], cores: int, gpu_jobs: set[int] = frozenset(), gpus: int = 0) -> float:
    """Makespan (s) of a list schedule: ready jobs start longest-path first
    on `cores` one-core slots; jobs in `gpu_jobs` use one of `gpus` GPU
    slots instead."""
    level = bottom_levels(durations, parents)
    waiting = {n: len(set(parents.get(n, []))) for n in durations}
    children = defaultdict(set)
    for child, ps in parents.items():
        for p in ps:
            children[p].add(child)
    ready = [(-level[n], n) for n, k in waiting.items() if k == 0]
    heapq.heapify(ready)
    free = {"cpu": cores, "gpu": gpus}
    running: list[tuple[float, int]] = []
    now, held = 0.0, []
    while ready or running:
        held = []
        while ready:
            prio, n = heapq.heappop(ready)
            pool = "gpu" if n in gpu_jobs else "cpu"
            if free[pool] > 0:
                free[pool] -= 1
                heapq.heappush(running, (now + durations[n], n))
            else:
                held.append((prio, n))
        for item in held:
            heapq.heappush(ready, item)
        now, n = heapq.heappop(running)
        free["gpu" if n in gpu_jobs else "cpu"] += 1
        for c in children[n]:
            waiting[c] -= 1
            if waiting[c] == 0:
                heapq.heappush(ready, (-level[c], c))
    return now


def print_projection(fitted: dict, jobs: pd.DataFrame, args: argparse.Namespace) -> None:
    cfg = paper_config(args.configfile)
    from snakemake.utils import update_config

    extra: dict = {}
    for path in args.configfile:
        update_config(extra, yaml.safe_load((REPO / path).read_text()))
    on_gpus = {**extra, "train": {**extra.get("train", {}), "gpus": 1}}
    dot, cpu_run, gpu_run = scratch_snakemake([(["--dag"], extra), (["-n"], extra), (["-n"], on_gpus)])
    print_requests(cpu_run, "train.gpus 0")
    print_requests(gpu_run, "train.gpus 1")
    nodes, parents = paper_dag(dot)
    pjobs = paper_jobs(nodes, parents, cfg, jobs)
    cpu = {n: job_cost(j, fitted, "cpu_s") for n, j in pjobs.items()}
    unmodelled = defaultdict(int)
    for n, c in cpu.items():
        if c is None and nodes[n]["rule"] != "all":
            unmodelled[nodes[n]["rule"]] += 1
    dur = {n: (c or 0.0) for n, c in cpu.items()}
    stage = {n: f"{j['rule']} {j['model']}".strip() for n, j in pjobs.items()}
    print(f"\nThe paper preset ({len(nodes)} jobs, rule all): projected CPU time per stage")
    for key in sorted(set(stage.values()), key=lambda k: -sum(dur[n] for n in dur if stage[n] == k)):
        mine = [dur[n] for n in dur if stage[n] == key]
        if sum(mine) > 0:
            print(f"  {key:<20}{len(mine):>5} jobs {sum(mine) / 3600:>9.1f} CPU-h  (longest job {max(mine) / 3600:.2f} h)")
    print(f"  not modelled (no benchmark file, or not measured in these runs; counted as 0 s): {dict(unmodelled)}")
    all_cpu = sum(dur.values())
    crit = max(bottom_levels(dur, parents).values())
    print(f"  in all {all_cpu / 3600:.1f} CPU-h; critical path {crit / 3600:.1f} h")
    for cores in (2, 16):
        print(f"  {cores} cores: {list_schedule(dur, parents, cores) / 3600:.1f} h (list schedule; total / cores = {all_cpu / cores / 3600:.1f} h)")
    train = {n for n, j in pjobs.items() if j["rule"] == "train" and uses_gpu(j["model"])}
    over = args.submit_overhead_s
    speedup = {n: costs.gpu_speedup(cfg["cluster"]["gpu_speedup"], j["rule"], j["model"], j["task"], gpus=int(n in train)) for n, j in pjobs.items()}
    gpu_dur = {n: d / speedup[n] + over for n, d in dur.items()}
    on_gpu = defaultdict(float)
    for n in train:
        on_gpu[pjobs[n]["model"]] += gpu_dur[n]
    print("  training on GPUs at the measured speed-ups (cluster.gpu_speedup): " + ", ".join(f"{m} {s / 3600:.1f} GPU-h" for m, s in on_gpu.items()))
    cores, gpus = args.nodes * args.node_cores, args.nodes * args.node_gpus
    print(
        f"  SLURM, {args.nodes} nodes x {args.node_cores} cores, {gpus} GPUs (training cells on GPUs, "
        f"each job +{over:g} s submission overhead): {list_schedule(gpu_dur, parents, cores, train, gpus) / 3600:.1f} h; "
        f"critical path {max(bottom_levels(gpu_dur, parents).values()) / 3600:.1f} h"
    )
    cpu_only = {n: d + over for n, d in dur.items()}
    print(f"  SLURM, {args.nodes} nodes x {args.node_cores} cores, no GPUs: {list_schedule(cpu_only, parents, cores) / 3600:.1f} h")


def write_cost_table(path: Path, fitted: dict, runs: list[str]) -> None:
    """The cost table the rules' SLURM requests come from (denali_pipe.workflow.costs)."""

    def rounded(m):
        return {k: rounded(v) if isinstance(v, dict) else float(f"{v:.4g}") for k, v in m.items()}

    rules = {r: rounded(m) for r, m in fitted.items() if r != "train"}
    rules["train"] = rounded(fitted["train"])
    header = (
        "# Per-job cost models (CPU seconds, peak RSS in MB) linear in each job's work\n"
        "# (src/denali_pipe/workflow/costs.py), fitted on the runs below by\n"
        f"#   python scripts/bench_stages.py fit ... --write-costs {path}\n"
        "# (docs/performance.md: the runs, their machine, the fit's check). Regenerate, do not edit.\n"
    )
    path.write_text(header + yaml.safe_dump({"runs": runs, "rules": rules}, sort_keys=False))


def main() -> None:
    if sys.argv[1:2] == ["run"]:
        run_snakemake(sys.argv[3:] if sys.argv[2:3] == ["--"] else sys.argv[2:])
        return
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mode", choices=["fit", "project"])
    ap.add_argument("runs", nargs="*", type=Path, help="workflow folders of finished runs made with `run` (project: one run, any)")
    ap.add_argument("--coarse", nargs="*", type=Path, default=[], help="runs made by plain snakemake (CPU times extrapolated)")
    ap.add_argument("--check", help="a run's folder name: compare it with the models fitted on the others")
    ap.add_argument("--configfile", nargs="*", default=[], help="config files over the paper preset for the projection")
    ap.add_argument("--nodes", type=int, default=4)
    ap.add_argument("--node-cores", type=int, default=16)
    ap.add_argument("--node-gpus", type=int, default=1)
    ap.add_argument(
        "--submit-overhead-s", type=float, default=10.0, help="per SLURM job: queueing and the job step's own Snakemake (measured 7-9 s: docs/cluster.md)"
    )
    ap.add_argument("--write-costs", type=Path)
    ap.add_argument("--no-projection", action="store_true", help="skip the paper preset's DAG (a minute of dry runs)")
    args = ap.parse_args()
    if args.mode == "project":
        cfg = paper_config(args.configfile)
        fitted = costs.load_costs(REPO / cfg["cluster"]["costs"])["rules"]
        print_projection(fitted, pd.concat([measured_jobs(r, coarse=True) for r in args.runs], ignore_index=True), args)
        return
    jobs = pd.concat([measured_jobs(r, coarse=False) for r in args.runs] + [measured_jobs(r, coarse=True) for r in args.coarse], ignore_index=True)
    fitted = fit_models(jobs[jobs.run != args.check] if args.check else jobs)
    print_throughput(jobs, fitted)
    if args.check:
        print_check(jobs, args.check)
    if args.write_costs:  # first: the projection's DAG build reads it
        runs = [f"{r.name}: {run_scale(r)['locations']} locations, {'coarse' if r in args.coarse else 'fine'} sampling" for r in [*args.runs, *args.coarse]]
        write_cost_table(args.write_costs, fitted, runs)
    if not args.no_projection:
        print_projection(fitted, jobs, args)


if __name__ == "__main__":
    main()
