# Preprocessing: the crop window per resolution (from the background sets),
# then one job per object capture set (align, subtract its NOOBJECT set,
# crop), then the benchmark's samples per resolution.


rule crop_window:
    input:
        backgrounds=lambda w: [store(s.name) for s in SETS if s.object == "NOOBJECT" and s.resolution == w.res],
        scene="results/calibration/scene.json",
    output:
        "results/features/crop_{res}.json",
    log:
        "logs/features/crop_{res}.log",
    params:
        time_axis=TIME_AXIS_ARG,
    shell:
        "{DENALI} crop-window {input.backgrounds} --scene {input.scene} {params.time_axis} --out {output} > {log} 2>&1"


rule preprocess:
    input:
        store=store("{set}"),
        background=background_store,
        crop=lambda w: f"results/features/crop_{parse_set_name(w.set).resolution}.json",
    output:
        directory("results/features/{set}.zarr"),
    log:
        "logs/preprocess/{set}.log",
    benchmark:
        "benchmarks/preprocess/{set}.tsv"
    resources:
        runtime=request_runtime("preprocess"),
        mem_mb=request_mem_mb("preprocess"),
    shell:
        "{DENALI} preprocess {input.store} --background {input.background} --crop {input.crop} --out {output} > {log} 2>&1"


rule dataset:
    input:
        features=lambda w: [f"results/features/{name}.zarr" for name in benchmark_sets(w.res)],
        positions="results/calibration/tag1_positions.parquet",
        sheet=config["objects_sheet"],
    output:
        x=directory("results/datasets/{res}.zarr"),
        table="results/datasets/{res}.parquet",
    log:
        "logs/datasets/{res}.log",
    shell:
        "{DENALI} dataset {input.features} --positions {input.positions} --objects-sheet {input.sheet}" " --out {output.x} --table {output.table} > {log} 2>&1"
