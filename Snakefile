# denali-pipe: every table and figure of the DENALI paper as one DAG.
# `snakemake --cores all` builds `all`; any single target works too, e.g.
# `snakemake --cores all results/table4.csv`. `snakemake --report
# results/report.html` collects every table and figure with its caption.


from denali_pipe.cli import warm_start
from denali_pipe.workflow.scheduler_timer import keep_one_reevaluation_timer
from denali_pipe.workflow.targets import target_files

# Snakemake's scheduler starts a timer chain per finished job and its main
# process ends up scheduling on a quarter of a 2-core machine (the module says why).
keep_one_reevaluation_timer()


report: "report/workflow.rst"


include: "rules/common.smk"
include: "rules/sensor.smk"
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
include: "rules/release_models.smk"
include: "rules/tsne.smk"
include: "rules/jitter.smk"
include: "rules/stability.smk"


rule all:
    default_target: True
    input:
        # every paper artefact, from the one table `denali targets` lists
        target_files(TWIN_PAIRS),


# Jobs fork from one warm interpreter instead of each importing torch and
# friends afresh (config `warm_start`); local runs only, since cluster jobs
# run on other machines.
onstart:
    warm_start.start(config["warm_start"] and workflow.local_exec, Path("logs/warm_start.log"))


onsuccess:
    warm_start.stop()


onerror:
    warm_start.stop()
