# The TMF882x sensor fitted to real raw histograms (config sensor; docs/sensor.md).
from denali_pipe.sensor.captures import SWEEP


def sensor_inputs(wildcards):
    # the real sweep where the folder holds one; else nothing, and the target says so
    sweep = Path(config["sensor"]["real_dir"]) / SWEEP
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
        # the fit's own keys: the time axis reruns no fit
        s={k: config["sensor"][k] for k in ("real_dir", "held_out_every", "min_distance_m", "rounds")},
    shell:
        "{DENALI} sensor-fit {params.s[real_dir]:q} --held-out-every {params.s[held_out_every]} --min-distance-m {params.s[min_distance_m]}"
        " --rounds {params.s[rounds]} --out {output.json} > {log} 2>&1"


def scene_inputs(wildcards):
    # every scene's captures and mesh in the folder (none where it is absent: the target says so)
    folder = Path(config["sensor"]["real_dir"])
    if not folder.is_dir():
        return []
    return sorted(str(p) for p in folder.glob("*.npz") if p.name != SWEEP) + sorted(str(p) for p in folder.glob("*.stl"))


rule sensor_vs_real:
    input:
        fit="results/sensor_fit.json",
        scenes=scene_inputs,
    output:
        csv="results/sensor_vs_real.csv",
        png=report("results/sensor_vs_real.png", caption="../report/sensor_vs_real.rst", category="1. Captures"),
    log:
        "logs/sensor/sensor_vs_real.log",
    benchmark:
        "benchmarks/sensor/sensor_vs_real.tsv"
    params:
        real_dir=config["sensor"]["real_dir"],
    shell:
        "{DENALI} sensor-vs-real {params.real_dir:q} --fit {input.fit} --out {output.csv} > {log} 2>&1"
