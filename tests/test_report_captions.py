"""The HTML report's captions (report/*.rst): every caption renders as
Snakemake renders it (Jinja with trim_blocks/lstrip_blocks, then docutils)
for every preset and both training protocols, without a markup error."""

from types import SimpleNamespace

import pytest
from conftest import REPO
from docutils.core import publish_parts
from jinja2 import Environment, StrictUndefined
from test_config import PRESETS, load, merged

from denali_pipe.train.conditions import TABLES as CONDITION_TABLES

CAPTIONS = sorted((REPO / "report").glob("*.rst"))


@pytest.mark.parametrize("protocol", ["clean", "paper"])
@pytest.mark.parametrize("preset", PRESETS, ids=lambda p: p.stem)
@pytest.mark.parametrize("caption", CAPTIONS, ids=lambda p: p.stem)
def test_caption_renders(caption, preset, protocol):
    config = merged({**load(preset), "train": {**load(preset).get("train", {}), "protocol": protocol}})
    # StrictUndefined: a misspelt config key fails here instead of printing nothing
    env = Environment(trim_blocks=True, lstrip_blocks=True, undefined=StrictUndefined)
    wildcards = {
        "training_curves": [{"fig": f} for f in ("fig16", "fig17")],
        "tsne": [{"fig": f} for f in ("fig13", "fig14")],
        "condition_table": [{"table": t} for t in CONDITION_TABLES],
    }
    for w in wildcards.get(caption.stem, [{}]):
        text = env.from_string(caption.read_text()).render(snakemake=SimpleNamespace(config=config, wildcards=SimpleNamespace(**w)))
        # halt_level 2: a docutils warning (e.g. `|z|` read as a substitution) raises
        html = publish_parts(text, writer="html", settings_overrides={"halt_level": 2, "report_level": 5})["body"]
        assert f"{config['preset']}</tt>" in html or caption.stem == "workflow"
        if caption.stem in (
            "table5",
            "table2",
            "table10",
            "training_curves",
            "speed_vs_accuracy",
            "condition_table",
            "jitter",
            "workflow",
            "fig10",
            "fig11",
            "tsne",
        ):
            assert f">{protocol}</tt>" in html
