# Where the run's methods fail (report/stability.py): every training cell
# that rule all trains, the sim-to-real fit and the twin's calibration.


def run_cells():
    """metrics.json of every training cell of rule all: Tables 2, 5 and 10's
    and the speed chart's (with the linear model), Figs 13-14's at each
    resolution, Tables 7-9's and the jitter sweep's."""
    files = run_files([*TRAINED_MODELS, LINEAR], TASKS, ["random"]) + run_files([BENCHMARK_MODEL], TASKS, SPLITS)
    files += [f for res in TSNE_RESOLUTION.values() for f in run_files([BENCHMARK_MODEL], ["shape"], ["random"], res=res)]
    files += [f for table in CONDITION_TABLES for f in condition_table_metrics(SimpleNamespace(table=table))]
    return sorted(set(files + jitter_metrics(None)))


rule stability:
    input:
        cells=lambda w: run_cells(),
        transforms="results/transforms.json",
        calibration="results/twin_calibration.json",
    output:
        png=report("results/stability.png", caption="../report/stability.rst", category="8. Stability"),
        csv="results/stability.csv",
    log:
        "logs/report/stability.log",
    shell:
        "{DENALI} stability {input.cells} --transforms {input.transforms} --calibration {input.calibration} --out {output.png} > {log} 2>&1"
