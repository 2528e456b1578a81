"""The workflow's config outside Snakemake (for the verbs people call): the
defaults file with `--configfile` files merged over it key by key and
validated by the schema beside it, as Snakemake does for a run."""

from __future__ import annotations

from pathlib import Path

DEFAULTS = Path("config/config.yaml")
SCHEMA_NAME = "schema.yaml"


def load_config(configfiles: list[str | Path] = (), defaults: str | Path = DEFAULTS) -> dict:
    """`defaults` (relative to the working directory, the repository root as
    for `snakemake`), each of `configfiles` merged over it in order, then
    validated (and its unset keys filled) by the schema beside `defaults`."""
    import yaml
    from snakemake.utils import update_config, validate

    defaults = Path(defaults)
    config = {}
    for path in (defaults, *map(Path, configfiles)):
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no such config file (run from the repository root, or pass --defaults)")
        update_config(config, yaml.safe_load(path.read_text()) or {})
    validate(config, str(defaults.parent / SCHEMA_NAME))
    return config
