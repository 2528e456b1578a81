# Sim-to-real: the transforms fitted on real 3x3 light-on captures paired with
# their twins (results/transforms.json), and Fig 9 (a 1D CNN localiser trained
# on twins at each fidelity plus a few real samples, scored on real captures).

FIT = config["fit"]


def fit_sets():
    """The 3x3 light-on base-object capture sets: the real side of the pairs.
    Drawn when a fit rule is needed, so a config without them fails only then."""
    sets = [s for s in SETS if s.name in benchmark_sets("3x3") and s.light_on]
    if not sets:
        raise ValueError("the sim-to-real fit needs 3x3 light-on base-object capture sets (config `resolutions`, `lightings`, `objects`)")
    return sets


def fit_inputs(wildcards):
    sets = fit_sets()
    return {
        "features": [f"results/features/{s.name}.zarr" for s in sets],
        "twins": sorted({f"results/twin/{s.object}_{s.size}.zarr" for s in sets}),
    }


# The fit's and Fig 9's settings: one JSON each, so that a Fig 9 setting reruns no fit.
FIT_JOB_CONFIG = json.dumps({"seed": config["seed"], "fit": {k: FIT[k] for k in ("test_fraction", "min_sim_fraction")}}, sort_keys=True)
FIG9_JOB_CONFIG = json.dumps({"seed": config["seed"], "fit": FIT}, sort_keys=True)
# The localiser's optimiser settings are the benchmark's 1D CNN location ones; epochs are Fig 9's own.
FIG9_HYPER = json.dumps({**TRAIN["hyper"]["cnn1d"]["location"], "epochs": FIT["fig9"]["epochs"]}, sort_keys=True)


rule transforms:
    input:
        unpack(fit_inputs),
    output:
        "results/transforms.json",
    params:
        config=FIT_JOB_CONFIG,
    log:
        "logs/fit/transforms.log",
    benchmark:
        "benchmarks/fit/transforms.tsv"
    conda:
        "../envs/denali.yaml"
    shell:
        "denali fit-transforms --features {input.features} --twins {input.twins} --config {params.config:q} --out {output} > {log} 2>&1"


rule fig9:
    input:
        unpack(fit_inputs),
        positions="results/calibration/tag1_positions.parquet",
        transforms="results/transforms.json",
    output:
        png="results/fig9.png",
        csv="results/fig9.csv",
    params:
        config=FIG9_JOB_CONFIG,
        hyper=FIG9_HYPER,
    # models this small train best single-threaded beside other jobs (see train.threads)
    threads: config["train"]["threads"]
    log:
        "logs/fit/fig9.log",
    benchmark:
        "benchmarks/fit/fig9.tsv"
    conda:
        "../envs/denali.yaml"
    shell:
        "denali fig9 --features {input.features} --twins {input.twins} --positions {input.positions} --transforms {input.transforms}"
        " --config {params.config:q} --hyper {params.hyper:q} --threads {threads} --out {output.png} > {log} 2>&1"
