# The synthetic capture rig: one job per object, size and SPAD resolution,
# writing those capture sets (every configured lighting) in the release layout.
# Per resolution, not per object and size: the benchmark tables read one
# resolution (train.resolution), so `make run` synthesises only its sets.


if config["source"] == "synthetic":

    rule rig:
        input:
            meshes=rig_mesh_files,
            # the release poses.json the tracked scene follows (rig.scene_poses), so that its edits rerun the rig
            scene_poses=[config["rig"]["scene_poses"]] if config["rig"]["scene_poses"] else [],
        output:
            [directory(raw_set(f"{{object}}_{{size}}_{{res}}_{light}")) for light in config["lightings"]],
        log:
            "logs/rig/{object}_{size}_{res}.log",
        benchmark:
            "benchmarks/rig/{object}_{size}_{res}.tsv"
        resources:
            runtime=request_runtime("rig"),
            mem_mb=request_mem_mb("rig"),
        params:
            object=rig_object_arg,
            config=json.dumps({"seed": config["seed"], "rig": config["rig"]}, sort_keys=True),
            time_axis=TIME_AXIS_ARG,
        shell:
            "{DENALI} rig {output} {params.object} --config {params.config:q} {params.time_axis} > {log} 2>&1"


rule rig_examples:
    input:
        sets=[obj for obj, _ in example_pairs()],
        backgrounds=[bg for _, bg in example_pairs()],
    output:
        png=report("results/rig_examples.png", caption="../report/rig_examples.rst", category="1. Captures"),
        csv="results/rig_examples.csv",
    log:
        "logs/rig_examples.log",
    params:
        time_axis=TIME_AXIS_ARG,
    shell:
        "{DENALI} rig-examples --sets {input.sets} --backgrounds {input.backgrounds} {params.time_axis} --out {output.png} > {log} 2>&1"


rule rig_vs_real:
    input:
        sets=[obj for obj, _ in rig_vs_real_pairs()],
        backgrounds=[bg for _, bg in rig_vs_real_pairs()],
        feature_stats=feature_stats_files(),
        release_models="results/release_models.csv",
    output:
        png=report("results/rig_vs_real.png", caption="../report/rig_vs_real.rst", category="1. Captures"),
        csv="results/rig_vs_real.csv",
    log:
        "logs/rig_vs_real.log",
    params:
        feature_stats=feature_stats_arg(),
    shell:
        "{DENALI} rig-vs-real --sets {input.sets} --backgrounds {input.backgrounds} --png {output.png} --csv {output.csv} {params.feature_stats}"
        " --release-models {input.release_models} > {log} 2>&1"
