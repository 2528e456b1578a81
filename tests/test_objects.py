"""Tests of the object catalogue."""

from __future__ import annotations

from pathlib import Path

import pytest

from denali_pipe.core import objects as O

HEADER = "\t".join(O.COLUMNS)


# --- catalogue -----------------------------------------------------------------


def test_constants():
    assert O.BASE_SHAPES == tuple(sorted(O.BASE_SHAPES)) and len(O.BASE_SHAPES) == 30
    assert O.SIZES == {"4inch": 0.1016, "8inch": 0.2032}
    assert O.MATERIALS["retroreflective"] == O.Material(0.15, 0.6)
    assert O.BACKGROUNDS == ("NOOBJECT", "NOOBJECTMOUNT")


def test_catalogue_contents(catalogue):
    assert len(catalogue) == 35
    for c in O.BASE_SHAPES:
        s = catalogue[c]
        assert (s.cls, s.sizes, s.variant, s.material, s.mesh) == (c, ("4inch", "8inch"), "base", "retroreflective", None)
    for c in ("1", "A", "circle"):
        s = catalogue[f"generalization{c}italic"]
        assert (s.cls, s.sizes, s.variant, s.italic) == (c, ("8inch",), "italic", True)
    for m in ("cardstock", "white"):
        s = catalogue[f"generalization1{m}"]
        assert (s.cls, s.sizes, s.variant, s.material) == ("1", ("4inch", "8inch"), "nonrr", m)
        assert s.material_params.rho_retro == 0.0
    assert catalogue["A"].type == "letter" and catalogue["7"].type == "number" and catalogue["plus"].type == "shape"


def write_sheet(tmp_path, *rows: str) -> Path:
    p = tmp_path / "objects.tsv"
    p.write_text("\n".join([HEADER, *rows]) + "\n")
    return p


@pytest.mark.parametrize(
    "row, column, expected",
    [
        ("A\tA\tletter\t4inch\tbase\tshiny\t", "material", "one of"),
        ("A\tA\tletter\t4inch,6inch\tbase\tretroreflective\t", "sizes", "one of"),
        ("A\tA\tletter\t\tbase\tretroreflective\t", "sizes", "at least 1"),
        ("A\tA\tletter\t4inch\tbold\tretroreflective\t", "variant", "one of"),
        ("A\tZ\tletter\t4inch\tbase\tretroreflective\t", "class", "BASE_SHAPES"),
        ("A\tA\tnumber\t4inch\tbase\tretroreflective\t", "type", "'letter'"),
    ],
)
def test_catalogue_rejects_bad_row(tmp_path, row, column, expected):
    good = "B\tB\tletter\t4inch,8inch\tbase\tretroreflective\t"
    sheet = write_sheet(tmp_path, good, row)
    with pytest.raises(ValueError) as e:
        O.load_catalogue(sheet)
    msg = str(e.value)
    assert str(sheet) in msg and "row 2 (line 3)" in msg and f"column '{column}'" in msg and expected in msg, msg


def test_catalogue_rejects_duplicates_and_bad_header(tmp_path):
    row = "B\tB\tletter\t4inch\tbase\tretroreflective\t"
    with pytest.raises(ValueError, match=r"row 2 \(line 3\), column 'name'.*duplicate"):
        O.load_catalogue(write_sheet(tmp_path, row, row))
    (tmp_path / "objects.tsv").write_text("name\tclass\n")
    with pytest.raises(ValueError, match="columns"):
        O.load_catalogue(tmp_path / "objects.tsv")


def test_spec_travels_as_json(catalogue):
    import json

    for spec in catalogue.values():
        assert O.spec_from_dict(json.loads(json.dumps(spec.to_dict()))) == spec
