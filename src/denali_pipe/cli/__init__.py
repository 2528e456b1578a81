"""`denali`: the verbs people call, and one verb per pipeline stage.

The verbs for people (`targets`, `check-release`, `explore`) come first. The
stage verbs are what the workflow's rules call, one module per file of
`rules/` (rule x -> `denali x` -> module x), each a thin call into the
library; the rules pass the (already validated) config subset a stage needs
as JSON, so that a changed setting reruns exactly the jobs that use it.
"""

from __future__ import annotations

import argparse
import logging

from denali_pipe.cli import (
    explore,
    export,
    fig9,
    fit,
    generalisation,
    ingest,
    jitter,
    poses,
    predict,
    preprocess,
    release,
    release_models,
    report,
    rig,
    sensor,
    stability,
    targets,
    train,
    tsne,
    twin,
)

log = logging.getLogger("denali")

# Verbs for people, then the stage verbs in the order the DAG runs them.
USER_MODULES = (targets, release, predict, export, explore)
STAGE_MODULES = (sensor, rig, ingest, poses, preprocess, train, report, twin, fit, fig9, generalisation, release_models, tsne, jitter, stability)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="denali", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="verb", required=True, metavar="VERB")
    for module in USER_MODULES:
        module.register(sub)
    user_verbs = list(sub.choices)
    for module in STAGE_MODULES:
        module.register(sub)
    stage_verbs = [v for v in sub.choices if v not in user_verbs]
    p.epilog = f"for people: {', '.join(user_verbs)}; stages (called by the workflow's rules): {', '.join(stage_verbs)}"
    return p


def main(argv: list[str] | None = None) -> int:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    args = build_parser().parse_args(argv)
    try:
        args.func(args)
    except (ValueError, FileNotFoundError, OSError) as e:
        log.error("%s", e)
        return 1
    return 0
