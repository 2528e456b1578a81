# Where the run's methods fail (report/stability.py): every training cell
# that rule all trains, the sim-to-real fit and the twin's calibration.


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
