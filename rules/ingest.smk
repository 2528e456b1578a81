# Raw-capture ingestion: one job per capture set into a Zarr store and its
# capture index, then the aggregates over all sets.


rule ingest:
    input:
        raw_source,
    output:
        store=directory(store("{set}")),
        index="results/index/{set}.parquet",
    log:
        "logs/ingest/{set}.log",
    benchmark:
        "benchmarks/ingest/{set}.tsv"
    resources:
        runtime=request_runtime("ingest"),
        mem_mb=request_mem_mb("ingest"),
    params:
        object=ingest_object_arg,
    shell:
        "{DENALI} ingest {input} {params.object} --store {output.store} --index {output.index} > {log} 2>&1"


rule index:
    input:
        expand("results/index/{set}.parquet", set=SET_NAMES),
    output:
        "results/index/captures.parquet",
    log:
        "logs/index.log",
    shell:
        "{DENALI} index {input} --out {output} > {log} 2>&1"


rule table4:
    input:
        [store(name) for name in SET_NAMES],
    output:
        report("results/table4.csv", caption="../report/table4.rst", category="1. Captures"),
    log:
        "logs/table4.log",
    shell:
        "{DENALI} table4 {input} --out {output} > {log} 2>&1"
