# The timing-jitter sweep (paper Sec 5.2, supplement 11.6): 1D CNN cells
# (rule train) on the 3x3 light-on centre zone blurred by each FWHM
# (conditions jitter<F>ps), gathered into each task's metrics against FWHM.


rule jitter:
    input:
        jitter_metrics,
    output:
        png=report("results/jitter.png", caption="../report/jitter.rst", category="3. Training"),
        csv="results/jitter.csv",
    log:
        "logs/jitter/jitter.log",
    params:
        time_axis=TIME_AXIS_ARG,
    shell:
        "{DENALI} jitter {input} {params.time_axis} --out {output.png} > {log} 2>&1"
