# denali-pipe: every table and figure of the DENALI paper as one DAG.
# `snakemake --cores all` builds `all`; any single target works too, e.g.
# `snakemake --cores all results/table4.csv`.

include: "rules/common.smk"
include: "rules/rig.smk"
include: "rules/ingest.smk"
include: "rules/poses.smk"


rule all:
    input:
        "results/rig_examples.png",
        "results/index/captures.parquet",
        "results/table4.csv",
        "results/table6.csv",
        "results/fig12.png",
    default_target: True
