# The TMF882x sensor fitted to real raw histograms (config sensor; docs/sensor.md).


def sensor_inputs(wildcards):
    # the real sweep where the folder holds one; else nothing, and the target says so
    sweep = Path(config["sensor"]["real_dir"]) / "iccp_distance_sweep.npz"
    return [str(sweep)] if sweep.is_file() else []


rule sensor_fit:
    input:
        sensor_inputs,
    output:
        json="results/sensor_fit.json",
        png=report("results/sensor_fit.png", caption="../report/sensor_fit.rst", category="1. Captures"),
        csv="results/sensor_fit.csv",
    log:
        "logs/sensor/sensor_fit.log",
    benchmark:
        "benchmarks/sensor/sensor_fit.tsv"
    params:
        s=config["sensor"],
    shell:
        "{DENALI} sensor-fit {params.s[real_dir]:q} --held-out-every {params.s[held_out_every]} --min-distance-m {params.s[min_distance_m]}"
        " --rounds {params.s[rounds]} --out {output.json} > {log} 2>&1"
