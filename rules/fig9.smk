# Fig 9 (experiments/fig9.py): a 1D CNN localiser trained on twins at each
# fidelity of the fitted transforms plus a few real samples, scored on real
# captures.

# Fig 9's settings (the whole fit section: the split it shares with the fit).
FIG9_JOB_CONFIG = json.dumps({"seed": config["seed"], "fit": FIT}, sort_keys=True)


rule fig9:
    input:
        unpack(fit_inputs),
        positions="results/calibration/tag1_positions.parquet",
        transforms="results/transforms.json",
    output:
        png=report("results/fig9.png", caption="../report/fig9.rst", category="5. Sim-to-real"),
        csv="results/fig9.csv",
    log:
        "logs/fig9.log",
    benchmark:
        "benchmarks/fig9.tsv"
    priority: SERIAL_CHAIN_PRIORITY
    # models this small train best single-threaded beside other jobs (see train.threads)
    threads: config["train"]["threads"]
    params:
        config=FIG9_JOB_CONFIG,
        hyper=fig9_hyper,
        precision=config["train"]["precision"],
    shell:
        "{DENALI} fig9 --features {input.features} --twins {input.twins} --positions {input.positions} --transforms {input.transforms}"
        " --config {params.config:q} --hyper {params.hyper:q} --threads {threads} --precision {params.precision}"
        " --out {output.png} > {log} 2>&1"
