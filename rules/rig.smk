# The synthetic capture rig: one job per object and size, writing that object's
# capture sets (every configured resolution and lighting) in the release layout.


def rig_object_arg(wildcards):
    if wildcards.object in BACKGROUNDS:
        return ""
    return "--object " + shlex.quote(json.dumps(CATALOGUE[wildcards.object].to_dict(), sort_keys=True))


def rig_mesh_files(wildcards):
    spec = CATALOGUE.get(wildcards.object)
    if spec is None or spec.mesh is None:
        return []
    return [spec.mesh.format(size=wildcards.size, inch=wildcards.size.replace("inch", "in"))]


if config["source"] == "synthetic":

    rule rig:
        input:
            rig_mesh_files,
        output:
            [
                directory(raw_set(f"{{object}}_{{size}}_{res}_{light}"))
                for res in config["resolutions"]
                for light in config["lightings"]
            ],
        params:
            object=rig_object_arg,
            config=json.dumps({"seed": config["seed"], "rig": config["rig"]}, sort_keys=True),
        log:
            "logs/rig/{object}_{size}.log",
        shell:
            "denali synth {output} {params.object} --config {params.config:q} > {log} 2>&1"


def example_pairs():
    """One object set per resolution (lights on, 8 in and a solid shape where
    captured: the strongest returns) and its NOOBJECT background."""
    picks = {}
    objects = [s for s in SETS if not s.is_background]
    preference = lambda s: (s.light != "lighton", s.size != "8inch", CATALOGUE[s.object].type != "shape", s.name)
    for s in sorted(objects, key=preference):
        picks.setdefault(s.resolution, s)
    return [(raw_set(s.name), raw_set(background_of(s).name)) for s in picks.values()]


rule rig_examples:
    input:
        sets=[obj for obj, _ in example_pairs()],
        backgrounds=[bg for _, bg in example_pairs()],
    output:
        png="results/rig_examples.png",
        csv="results/rig_examples.csv",
    log:
        "logs/rig_examples.log",
    shell:
        "denali rig-examples --sets {input.sets} --backgrounds {input.backgrounds} --out {output.png} > {log} 2>&1"
