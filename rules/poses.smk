# Tracking poses: AprilTag detection and PnP per capture set, then one
# calibration over the light-on sets (world frame, z-score filtering, scene,
# Table 6, Fig 12) and detection rates over every set.


rule poses:
    input:
        store("{set}"),
    output:
        "results/poses/{set}.parquet",
    log:
        "logs/poses/{set}.log",
    benchmark:
        "benchmarks/poses/{set}.tsv"
    conda:
        "../envs/denali.yaml"
    shell:
        "denali poses {input} --out {output} > {log} 2>&1"


rule calibrate:
    input:
        poses=lit_pose_tables(),
        figure_store=store(figure_set()),
    output:
        positions="results/calibration/tag1_positions.parquet",
        scene="results/calibration/scene.json",
        table6="results/table6.csv",
        fig12="results/fig12.png",
    log:
        "logs/calibrate.log",
    conda:
        "../envs/denali.yaml"
    shell:
        "denali calibrate {input.poses} --figure-store {input.figure_store} --outdir results/calibration"
        " --table6 {output.table6} --fig12 {output.fig12} > {log} 2>&1"


rule detections:
    input:
        [f"results/poses/{name}.parquet" for name in SET_NAMES],
    output:
        "results/calibration/detections.csv",
    log:
        "logs/detections.log",
    conda:
        "../envs/denali.yaml"
    shell:
        "denali detections {input} --out {output} > {log} 2>&1"
