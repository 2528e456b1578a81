# Digital twins: one job per object and size rendering every zone at every
# calibrated location (at the design geometry, and calibrated from the
# training captures), the twin's calibration, the renderers' cost vs
# fidelity benchmark, and Fig 18.

from denali_pipe.twin.selection import RESOLUTION as TWIN_RESOLUTION, fig18_sets, twin_pairs

TWIN_PAIRS = twin_pairs(CATALOGUE, config)
TWIN_MESHES = [f for name, size in TWIN_PAIRS for f in rig_mesh_files(SimpleNamespace(object=name, size=size))]
# A twin job gets the scene settings and its renderer's own section only, so
# that e.g. mitransient's spp reruns no analytic twin.
TWIN = config["twin"]
TWIN_SCENE_KEYS = ("wall_albedo", "object_albedo", "table", "table_albedo", "footprint", "material", "retroreflective", "illumination", "flood")
TWIN_JOB_CONFIG = json.dumps(
    {
        "seed": config["seed"],
        "resolutions": [TWIN_RESOLUTION],
        "twin": {
            **{k: TWIN[k] for k in ("renderer", *TWIN_SCENE_KEYS)},
            TWIN["renderer"]: TWIN[TWIN["renderer"]],
        },
    },
    sort_keys=True,
)
# Fig 18's captures are drawn when the rule is needed (input functions), so a
# config without light-on 3x3 sets fails only when Fig 18 is asked for.
FIG18 = lambda: fig18_sets(SETS, TWIN["fig18"]["n_captures"], config["seed"])


rule twin:
    input:
        scene="results/calibration/scene.json",
        meshes=rig_mesh_files,
    output:
        directory("results/twin/{object}_{size}.zarr"),
    log:
        "logs/twin/{object}_{size}.log",
    benchmark:
        "benchmarks/twin/{object}_{size}.tsv"
    params:
        object=rig_object_arg,
        config=TWIN_JOB_CONFIG,
        time_axis=TIME_AXIS_ARG,
    shell:
        "{DENALI} twin {input.scene} {params.object} --size {wildcards.size} --config {params.config:q} {params.time_axis} --out {output} > {log} 2>&1"


# The calibration's settings: the scene's, the material's and its own (analytic, so no renderer).
TWIN_CALIBRATION_CONFIG = json.dumps(
    {
        "seed": config["seed"],
        "fit": {"test_fraction": FIT["test_fraction"]},
        "twin": {k: TWIN[k] for k in (*TWIN_SCENE_KEYS, "calibration")},
    },
    sort_keys=True,
)


rule twin_calibration:
    input:
        unpack(calibration_inputs),
        scene="results/calibration/scene.json",
    output:
        json="results/twin_calibration.json",
        png=report("results/twin_calibration.png", caption="../report/twin_calibration.rst", category="4. Digital twin"),
        csv="results/twin_calibration.csv",
    log:
        "logs/twin_calibration.log",
    benchmark:
        "benchmarks/twin_calibration.tsv"
    priority: SERIAL_CHAIN_PRIORITY
    params:
        objects=lambda w: json.dumps(sorted((CATALOGUE[s.object].to_dict() for s in {s.object: s for s in fit_sets()}.values()), key=lambda d: d["name"])),
        config=TWIN_CALIBRATION_CONFIG,
        time_axis=TIME_AXIS_ARG,
    shell:
        "{DENALI} twin-calibration {input.scene} --features {input.features} --objects {params.objects:q} --config {params.config:q}"
        " {params.time_axis} --out {output.json} --png {output.png} > {log} 2>&1"


rule twin_calibrated:
    input:
        scene="results/calibration/scene.json",
        calibration="results/twin_calibration.json",
        meshes=rig_mesh_files,
    output:
        directory("results/twin_calibrated/{object}_{size}.zarr"),
    log:
        "logs/twin_calibrated/{object}_{size}.log",
    benchmark:
        "benchmarks/twin_calibrated/{object}_{size}.tsv"
    priority: SERIAL_CHAIN_PRIORITY
    params:
        object=rig_object_arg,
        config=TWIN_JOB_CONFIG,
        time_axis=TIME_AXIS_ARG,
    shell:
        "{DENALI} twin {input.scene} {params.object} --size {wildcards.size} --config {params.config:q} {params.time_axis}"
        " --calibration {input.calibration} --out {output} > {log} 2>&1"


rule render_benchmark:
    input:
        scene="results/calibration/scene.json",
        meshes=TWIN_MESHES,
    output:
        png=report("results/render_benchmark.png", caption="../report/render_benchmark.rst", category="4. Digital twin"),
        csv="results/render_benchmark.csv",
    log:
        "logs/render_benchmark.log",
    benchmark:
        "benchmarks/render_benchmark.tsv"
    priority: SERIAL_CHAIN_PRIORITY
    params:
        objects=json.dumps(sorted((CATALOGUE[name].to_dict() for name in dict.fromkeys(n for n, _ in TWIN_PAIRS)), key=lambda d: d["name"]), sort_keys=True),
        # every scene lit by the spot whatever twin.illumination says (twin/benchmark.py)
        config=json.dumps(
            {
                "seed": config["seed"],
                "sizes": config["sizes"],
                "twin": {k: v for k, v in TWIN.items() if k not in ("renderer", "fig18", "illumination", "flood")},
            },
            sort_keys=True,
        ),
        time_axis=TIME_AXIS_ARG,
    shell:
        "{DENALI} render-benchmark {input.scene} --objects {params.objects:q} --config {params.config:q} {params.time_axis} --out {output.png} > {log} 2>&1"


rule fig18:
    input:
        scene="results/calibration/scene.json",
        sets=lambda w: [store(s.name) for s in FIG18()],
        backgrounds=lambda w: [store(background_of(s).name) for s in FIG18()],
        twins=lambda w: [f"results/twin_calibrated/{s.object}_{s.size}.zarr" for s in FIG18()],
        calibration="results/twin_calibration.json",
        crop="results/features/crop_3x3.json",
    output:
        png=report("results/fig18.png", caption="../report/fig18.rst", category="4. Digital twin"),
        csv="results/fig18.csv",
    log:
        "logs/fig18.log",
    params:
        config=json.dumps({"seed": config["seed"], "variant": TWIN["mitransient"]["variant"], "fig18": TWIN["fig18"]}, sort_keys=True),
        time_axis=TIME_AXIS_ARG,
    shell:
        "{DENALI} fig18 {input.scene} --sets {input.sets} --backgrounds {input.backgrounds} --twins {input.twins}"
        " --calibration {input.calibration} --crop {input.crop} --config {params.config:q} {params.time_axis} --out {output.png} > {log} 2>&1"
