# Sim-to-real: the transforms fitted on real 3x3 light-on captures paired with
# their twins (results/transforms.json); Fig 9, which uses them, is in fig9.smk.


rule transforms:
    input:
        unpack(fit_inputs),
    output:
        report("results/transforms.json", caption="../report/transforms.rst", category="5. Sim-to-real"),
    log:
        "logs/fit/transforms.log",
    benchmark:
        "benchmarks/fit/transforms.tsv"
    priority: SERIAL_CHAIN_PRIORITY
    params:
        config=FIT_JOB_CONFIG,
        time_axis=TIME_AXIS_ARG,
    shell:
        "{DENALI} transforms --features {input.features} --twins {input.twins} --config {params.config:q} {params.time_axis} --out {output} > {log} 2>&1"
