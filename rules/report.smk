# Training tables and figures: aggregates over the training cells.
CURVE_TASK = {"fig16": "location", "fig17": "shape"}


rule table5:
    input:
        run_files([BENCHMARK_MODEL], TASKS, SPLITS),
    output:
        report("results/table5.csv", caption="../report/table5.rst", category="3. Training"),
    log:
        "logs/report/table5.log",
    shell:
        "{DENALI} report table5 {input} --out {output} > {log} 2>&1"


rule table2:
    input:
        run_files(TRAINED_MODELS, TASKS, ["random"]),
    output:
        report("results/table2.csv", caption="../report/table2.rst", category="3. Training"),
    log:
        "logs/report/table2.log",
    params:
        left_out=LEFT_OUT_ARG,
    shell:
        "{DENALI} report table2 {input} {params.left_out} --out {output} > {log} 2>&1"


rule table10:
    input:
        run_files(TRAINED_MODELS, TASKS, ["random"]),
    output:
        report("results/table10.csv", caption="../report/table10.rst", category="3. Training"),
    log:
        "logs/report/table10.log",
    params:
        left_out=LEFT_OUT_ARG,
    shell:
        "{DENALI} report table10 {input} {params.left_out} --out {output} > {log} 2>&1"


rule speed_vs_accuracy:
    input:
        run_files([*TRAINED_MODELS, LINEAR], TASKS, ["random"]),
    output:
        png=report("results/speed_vs_accuracy.png", caption="../report/speed_vs_accuracy.rst", category="3. Training"),
        csv="results/speed_vs_accuracy.csv",
    log:
        "logs/report/speed_vs_accuracy.log",
    params:
        left_out=LEFT_OUT_ARG,
    shell:
        "{DENALI} report speed-vs-accuracy {input} {params.left_out} --out {output.png} > {log} 2>&1"


rule training_curves:
    input:
        lambda w: run_files([BENCHMARK_MODEL], [CURVE_TASK[w.fig]], ["random"], "curves.csv"),
    output:
        png=report("results/{fig}.png", caption="../report/training_curves.rst", category="3. Training"),
        csv="results/{fig}.csv",
    log:
        "logs/report/{fig}.log",
    wildcard_constraints:
        fig="fig16|fig17",
    params:
        title=lambda w: shlex.quote(
            f"{BENCHMARK_LABEL} {CURVE_TASK[w.fig]} training curves ({TRAIN['resolution']}, random split, {TRAIN['protocol']} protocol)"
        ),
    shell:
        "{DENALI} report {wildcards.fig} {input} --title {params.title} --out {output.png} > {log} 2>&1"


rule condition_table:
    input:
        condition_table_metrics,
    output:
        report("results/{table}.csv", caption="../report/condition_table.rst", category="3. Training"),
    log:
        "logs/report/{table}.log",
    wildcard_constraints:
        table="|".join(CONDITION_TABLES),
    params:
        groups=" ".join(config["conditions"]["groups"]),
    shell:
        "{DENALI} report {wildcards.table} {input} --groups {params.groups} --out {output} > {log} 2>&1"
