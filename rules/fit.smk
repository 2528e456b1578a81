# Sim-to-real: the transforms fitted on real 3x3 light-on captures paired with
# their twins (results/transforms.json), and Fig 9 (a 1D CNN localiser trained
# on twins at each fidelity plus a few real samples, scored on real captures).

rule transforms:
    input:
        unpack(fit_inputs),
    output:
        report("results/transforms.json", caption="../report/transforms.rst", category="5. Sim-to-real"),
    params:
        config=FIT_JOB_CONFIG,
    log:
        "logs/fit/transforms.log",
    benchmark:
        "benchmarks/fit/transforms.tsv"
    shell:
        "{DENALI} fit-transforms --features {input.features} --twins {input.twins} --config {params.config:q} --out {output} > {log} 2>&1"


rule fig9:
    input:
        unpack(fit_inputs),
        positions="results/calibration/tag1_positions.parquet",
        transforms="results/transforms.json",
    output:
        png=report("results/fig9.png", caption="../report/fig9.rst", category="5. Sim-to-real"),
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
    shell:
        "{DENALI} fig9 --features {input.features} --twins {input.twins} --positions {input.positions} --transforms {input.transforms}"
        " --config {params.config:q} --hyper {params.hyper:q} --threads {threads} --out {output.png} > {log} 2>&1"
