# denali-pipe: every table and figure of the DENALI paper as one DAG.
# `snakemake --cores all` builds `all`; any single target works too, e.g.
# `snakemake --cores all results/table4.csv`. `snakemake --report
# results/report.html` collects every table and figure with its caption.


report: "report/workflow.rst"


include: "rules/common.smk"
include: "rules/rig.smk"
include: "rules/ingest.smk"
include: "rules/poses.smk"
include: "rules/twin.smk"
include: "rules/preprocess.smk"
include: "rules/train.smk"
include: "rules/report.smk"
include: "rules/fit.smk"
include: "rules/fig9.smk"
include: "rules/generalisation.smk"
include: "rules/tsne.smk"
include: "rules/jitter.smk"


rule all:
    default_target: True
    input:
        "results/rig_examples.png",
        "results/rig_vs_real.png",
        "results/index/captures.parquet",
        "results/table4.csv",
        "results/table6.csv",
        "results/fig12.png",
        "results/calibration/detections.csv",
        "results/table5.csv",
        "results/table2.csv",
        "results/table7.csv",
        "results/table8.csv",
        "results/table9.csv",
        "results/table10.csv",
        "results/fig16.png",
        "results/fig17.png",
        "results/speed_vs_accuracy.png",
        TWINS,
        "results/twin_calibration.png",
        CALIBRATED_TWINS,
        "results/render_benchmark.png",
        "results/fig18.png",
        "results/transforms.json",
        "results/fig9.png",
        "results/fig10.png",
        "results/fig11.png",
        "results/fig13.png",
        "results/fig14.png",
        "results/jitter.png",
