# Figs 10 and 11 (experiments/generalisation.py): the benchmark model's
# (train.benchmark_model) random-split cells, trained on the base objects, scored on the non-retroreflective
# (Fig 10) and italic (Fig 11) sets, each a dataset of its own.


rule variant_dataset:
    input:
        features=lambda w: [f"results/features/{name}.zarr" for name in variant_sets(w.variant, w.res)],
        positions="results/calibration/tag1_positions.parquet",
        sheet=config["objects_sheet"],
    output:
        x=directory("results/datasets/{variant}_{res}.zarr"),
        table="results/datasets/{variant}_{res}.parquet",
    log:
        "logs/datasets/{variant}_{res}.log",
    wildcard_constraints:
        variant="|".join(HELD_OUT),
    shell:
        "{DENALI} dataset {input.features} --variant {wildcards.variant} --positions {input.positions} --objects-sheet {input.sheet}"
        " --out {output.x} --table {output.table} > {log} 2>&1"


rule evaluate:
    input:
        model=f"{RUN_DIR}/model.pt",
        metrics=f"{RUN_DIR}/metrics.json",
        x=lambda w: dataset_files(w.dataset, w.protocol)["x"],
        table=lambda w: dataset_files(w.dataset, w.protocol)["table"],
    output:
        EVALUATION,
    log:
        f"logs/{EVALUATION.removeprefix('results/').removesuffix('.json')}.log",
    wildcard_constraints:
        dataset=rf"({'|'.join(HELD_OUT)})_(3x3|8x8)",
    params:
        run=lambda w, input: Path(input.model).parent,
    shell:
        "{DENALI} evaluate {params.run} {input.x} --table {input.table} --out {output} > {log} 2>&1"


rule fig10:
    input:
        **generalisation_inputs("fig10"),
        base_x=dataset_files(TRAIN["resolution"])["x"],
        base_table=dataset_files(TRAIN["resolution"])["table"],
    output:
        png=report("results/fig10.png", caption="../report/fig10.rst", category="6. Generalisation"),
        csv="results/fig10.csv",
    log:
        "logs/fig10.log",
    benchmark:
        "benchmarks/fig10.tsv"
    shell:
        "{DENALI} fig10 --cells {input.cells} --evaluations {input.evaluations} --variant-dataset {input.variant_x} --variant-table {input.variant_table}"
        " --base-dataset {input.base_x} --base-table {input.base_table} --out {output.png} > {log} 2>&1"


rule fig11:
    input:
        **generalisation_inputs("fig11"),
    output:
        png=report("results/fig11.png", caption="../report/fig11.rst", category="6. Generalisation"),
        csv="results/fig11.csv",
    log:
        "logs/fig11.log",
    benchmark:
        "benchmarks/fig11.tsv"
    shell:
        "{DENALI} fig11 --cells {input.cells} --evaluations {input.evaluations} --out {output.png} > {log} 2>&1"
