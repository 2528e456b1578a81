# denali-pipe: every table and figure of the DENALI paper as one DAG.
# `snakemake --cores all` builds `all`; any single target works too, e.g.
# `snakemake --cores all results/rig_examples.png`.

include: "rules/common.smk"
include: "rules/rig.smk"


rule all:
    input:
        raw_sets(),
        "results/rig_examples.png",
    default_target: True
