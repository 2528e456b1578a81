"""The hidden objects: the catalogue (the objects sheet, its specs) and the
plates' dimensions. Their outlines, meshes and face samples live in `meshes`;
this module imports neither shapely nor trimesh, so every job that only reads
the catalogue (most of them, and the Snakefile) starts without them.

Every object is a flat cut-out plate. Its LOCAL frame (the mesh frame that
`geometry.object_pose` maps to world) has the origin at the mount point,
+y up, and +z pointing AWAY from the relay wall, so the wall-facing side is
z = -THICKNESS / 2. Plates are extruded along z, centred on z = 0.

Units: metres throughout.
"""

from __future__ import annotations

import csv
import dataclasses
import functools
import os
from dataclasses import dataclass
from pathlib import Path

# --- catalogue constants ---------------------------------------------------------

SIZES = {"4inch": 0.1016, "8inch": 0.2032}  # largest dimension of the plate, m
THICKNESS = 0.0075  # plate thickness along local z, m
BOTTOM_Y = -0.0444  # local y of the plate's bottom edge (the origin is the mount point), m

BASE_SHAPES = (
    "0", "1", "2", "3", "4", "5", "6", "7", "8", "9",
    "A", "B", "C", "D", "E", "I", "O", "S", "U", "V",
    "circle", "downarrow", "halfcircle", "hexagon", "minus",
    "plus", "square", "triangle", "uparrow", "widerectangle",
)  # fmt: skip
# Capture-folder tokens of the scenes without an object. NOOBJECT still has the
# mount post in the scene; NOOBJECTMOUNT has nothing. The release labels both 8inch.
BACKGROUNDS = ("NOOBJECT", "NOOBJECTMOUNT")
BACKGROUND_SIZE = "8inch"

TYPES = ("number", "letter", "shape")
VARIANTS = ("base", "italic", "nonrr")
ITALIC_SHEAR_DEG = 12.0


@dataclass(frozen=True)
class Material:
    """Reflectance of a plate's face (both unitless, in [0, 1]).

    rho_diffuse: Lambertian albedo.
    rho_retro: fraction of the incident light returned into a narrow lobe
        around the incoming direction (retroreflection).
    """

    rho_diffuse: float
    rho_retro: float


# Reflectances at the TMF8828's 940 nm. The non-retroreflective plates are
# Lambertian with the diffuse reflectance their material has in the near
# infrared, where it differs from what the eye sees:
# - cardstock: cellulose paper stock scatters strongly and its dyes are
#   mostly transparent beyond ~800 nm; paper spectra in the USGS and
#   ECOSTRESS spectral libraries lie at 0.7-0.85 around 940 nm: 0.75;
# - white (white plastic sheet): TiO2-pigmented polymers (PVC, ABS, HIPS)
#   reflect 0.8-0.9 diffusely in the near infrared: 0.85;
# - manila (manila folder stock): unbleached, buff fibres, whose yellow
#   absorbs in the blue only; ~0.7 at 940 nm, a little below white paper.
MATERIALS = {
    "retroreflective": Material(rho_diffuse=0.15, rho_retro=0.6),
    "cardstock": Material(rho_diffuse=0.75, rho_retro=0.0),
    "white": Material(rho_diffuse=0.85, rho_retro=0.0),
    "manila": Material(rho_diffuse=0.7, rho_retro=0.0),
}

_REPO_CONFIG = Path(__file__).resolve().parents[3] / "config"
SCHEMA_NAME = "objects.schema.yaml"
COLUMNS = ("name", "class", "type", "sizes", "variant", "material", "mesh")


def class_type(cls: str) -> str:
    """`number`, `letter` or `shape` for a base class label."""
    if cls.isdigit():
        return "number"
    if len(cls) == 1 and cls.isalpha():
        return "letter"
    return "shape"


@dataclass(frozen=True)
class ObjectSpec:
    """One row of the objects sheet.

    name: the capture-folder token (e.g. `A`, `generalization1italic`).
    cls: base class label, one of BASE_SHAPES.
    type: `number`, `letter` or `shape`.
    sizes: the sizes captured, a tuple of SIZES keys.
    variant: `base`, `italic` or `nonrr`.
    material: a MATERIALS key.
    mesh: a mesh file path, or None for the procedural mesh. It may contain
        `{size}` (`4inch`) or `{inch}` (`4in`). The sheet gives it relative to
        its own folder; `load_catalogue` resolves it against that folder.
    """

    name: str
    cls: str
    type: str
    sizes: tuple[str, ...]
    variant: str
    material: str
    mesh: str | None = None

    def to_dict(self) -> dict:
        return {**dataclasses.asdict(self), "sizes": list(self.sizes)}

    @property
    def material_params(self) -> Material:
        return MATERIALS[self.material]

    @property
    def italic(self) -> bool:
        return self.variant == "italic"


# --- the objects sheet -----------------------------------------------------------


@functools.lru_cache(maxsize=None)
def _load_schema(path: str) -> dict:
    import yaml

    with open(path) as f:
        return yaml.safe_load(f)


def _find_schema(sheet: Path) -> Path:
    # A sheet may ship its own schema; otherwise use the repository's.
    for cand in (sheet.parent / SCHEMA_NAME, _REPO_CONFIG / SCHEMA_NAME):
        if cand.is_file():
            return cand
    raise FileNotFoundError(f"no {SCHEMA_NAME} beside {sheet} or in {_REPO_CONFIG}")


def _expected(err) -> str:
    """What a jsonschema error says the value should have been, in words."""
    v, s = err.validator, err.validator_value
    if v == "enum":
        return f"one of {list(s)}"
    if v == "pattern":
        return f"a value matching {s!r}"
    if v == "type":
        return f"type {s}"
    if v == "minItems":
        return f"at least {s} item(s)"
    if v == "uniqueItems":
        return "no repeated items"
    if v == "minLength":
        return "a non-empty value"
    return err.message


def _parse_row(row: dict[str, str]) -> dict:
    """Raw TSV strings -> the JSON document the schema validates."""
    sizes = row.get("sizes", "") or ""
    return {
        "name": row.get("name", ""),
        "class": row.get("class", ""),
        "type": row.get("type", ""),
        "sizes": [s.strip() for s in sizes.split(",")] if sizes.strip() else [],
        "variant": row.get("variant", ""),
        "material": row.get("material", ""),
        "mesh": (row.get("mesh") or "").strip() or None,
    }


def load_catalogue(path: str | os.PathLike, schema: str | os.PathLike | None = None) -> dict[str, ObjectSpec]:
    """Read and validate a TSV objects sheet.

    Columns: name class type sizes variant material mesh (sizes comma-separated,
    mesh may be empty). Blank lines and lines starting with `#` are skipped.
    Every row is validated against `schema` (default: `objects.schema.yaml`
    beside the sheet, else the repository's `config/objects.schema.yaml`).

    Returns {name: ObjectSpec} in sheet order. Raises ValueError listing every
    bad row as `<file>: row <n> (line <l>), column '<col>': expected <what>, got <value>`.
    """
    import jsonschema

    path = Path(path)
    schema_doc = _load_schema(str(Path(schema) if schema else _find_schema(path)))
    validator = jsonschema.Draft202012Validator(schema_doc)

    with open(path, newline="") as f:
        numbered = [(i, ln) for i, ln in enumerate(f.read().splitlines(), 1) if ln.strip() and not ln.startswith("#")]
    if not numbered:
        raise ValueError(f"{path}: empty objects sheet")
    header_line, header = numbered[0]
    cols = header.split("\t")
    if tuple(cols) != COLUMNS:
        raise ValueError(f"{path}: line {header_line}: expected the columns {list(COLUMNS)}, got {cols}")

    problems: list[str] = []
    specs: dict[str, ObjectSpec] = {}
    for n, (lineno, line) in enumerate(numbered[1:], 1):
        fields = next(csv.reader([line], delimiter="\t"))
        where = f"{path}: row {n} (line {lineno})"
        if len(fields) != len(COLUMNS):
            problems.append(f"{where}: expected {len(COLUMNS)} tab-separated columns, got {len(fields)}")
            continue
        doc = _parse_row(dict(zip(COLUMNS, fields)))
        errors = sorted(validator.iter_errors(doc), key=lambda e: list(e.absolute_path))
        for err in errors:
            col = err.absolute_path[0] if err.absolute_path else "?"
            value = doc.get(col) if isinstance(col, str) else None
            problems.append(f"{where}, column '{col}': expected {_expected(err)}, got {value!r}")
        if errors:
            continue
        if doc["class"] not in BASE_SHAPES:
            problems.append(f"{where}, column 'class': expected one of BASE_SHAPES, got {doc['class']!r}")
            continue
        if doc["type"] != class_type(doc["class"]):
            problems.append(f"{where}, column 'type': expected {class_type(doc['class'])!r} for class {doc['class']!r}, got {doc['type']!r}")
            continue
        mesh = doc["mesh"]
        if mesh and len(doc["sizes"]) > 1 and "{" not in mesh:
            # one file cannot be both sizes; the release keeps one file per size
            problems.append(f"{where}, column 'mesh': expected a {{size}} or {{inch}} placeholder for several sizes, got {mesh!r}")
            continue
        if doc["name"] in specs:
            problems.append(f"{where}, column 'name': expected a unique name, got duplicate {doc['name']!r}")
            continue
        specs[doc["name"]] = ObjectSpec(
            name=doc["name"],
            cls=doc["class"],
            type=doc["type"],
            sizes=tuple(doc["sizes"]),
            variant=doc["variant"],
            material=doc["material"],
            mesh=str(path.parent / mesh) if mesh else None,
        )
    if problems:
        raise ValueError("invalid objects sheet:\n" + "\n".join(problems))
    return specs


def spec_from_dict(d: dict) -> ObjectSpec:
    """Inverse of `ObjectSpec.to_dict` (how a sheet row travels to a job as JSON)."""
    return ObjectSpec(**{**d, "sizes": tuple(d["sizes"])})
