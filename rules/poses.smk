# Tracking poses: AprilTag detection and PnP per capture set; the calibration
# (world frame, z-score filtering, tag-1 positions, scene) from the light-on
# background sets; Table 6 and Fig 12 over every light-on set; detection rates
# over every set.


rule poses:
    input:
        store("{set}"),
    output:
        "results/poses/{set}.parquet",
    log:
        "logs/poses/{set}.log",
    benchmark:
        "benchmarks/poses/{set}.tsv"
    resources:
        runtime=request_runtime("poses"),
        mem_mb=request_mem_mb("poses"),
    shell:
        "{DENALI} poses {input} --out {output} > {log} 2>&1"


# Calibrated from the background sets only, which every configuration has and
# which visit every gantry location: the location labels and the twins then
# stay the same when objects are added (as the demo calibrates: 0.06/0.14/0.18 mm
# mean x/y/z error against the rig's truth on our design, 0.03/0.11/0.17 mm on
# a release's poses.json; docs/performance.md, "Tracking poses").
rule calibrate:
    input:
        calibration_pose_tables(),
    output:
        positions="results/calibration/tag1_positions.parquet",
        scene="results/calibration/scene.json",
    log:
        "logs/calibrate.log",
    shell:
        "{DENALI} calibrate {input} --outdir results/calibration > {log} 2>&1"


rule table6:
    input:
        poses=lit_pose_tables(),
        figure_store=store(figure_set()),
    output:
        table6=report("results/table6.csv", caption="../report/table6.rst", category="2. Tracking poses"),
        fig12=report("results/fig12.png", caption="../report/fig12.rst", category="2. Tracking poses"),
        fig12_data="results/fig12.csv",
    log:
        "logs/table6.log",
    shell:
        "{DENALI} table6 {input.poses} --figure-store {input.figure_store} --table6 {output.table6} --fig12 {output.fig12} > {log} 2>&1"


rule detections:
    input:
        [f"results/poses/{name}.parquet" for name in SET_NAMES],
    output:
        report("results/calibration/detections.csv", caption="../report/detections.rst", category="2. Tracking poses"),
    log:
        "logs/detections.log",
    shell:
        "{DENALI} detections {input} --out {output} > {log} 2>&1"
