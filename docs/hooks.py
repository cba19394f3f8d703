"""MkDocs hooks and the generator of the guide's pages that are made from the code, so they never
drift from it. ``python docs/hooks.py`` writes them into ``docs/guide/reference/`` (committed, so
the links work in an unbuilt checkout too); ``tests/test_docs.py`` checks the committed pages are
what this makes:

* ``reference/mapping.md`` is written from ``mappings/schema.json`` (every key, its type, allowed
  values, default and description, section by section as the schema's ``$defs`` go);
* ``reference/commands.md`` is the ``puppet`` command's own ``--help`` and each subcommand's,
  the subcommands read from the top-level help's choices (nothing is listed by hand);
* ``reference/faps.md``, the FAP glossary: each FAP's name, what it moves, its unit and direction
  (``puppet.fap.table``) and how far it goes on the default face (its rig's ``fap_reach``);
* ``reference/feature-points.md``: the feature points ``puppet rig`` needs
  (``puppet.face.landmarks.FDP_NEEDED``), each with what it is, beside their picture
  (``tools/figures/feature_point_picture.py``);
* on the device pages, a ``<!-- url-options: SCHEME -->`` line becomes the URL options that
  backend declares (``Device.OPTIONS``), when it declares them.

The code is asked in a child Python with the checkout first on its path, so the pages show this
checkout's code, not an installed snapshot. A ``--8<-- "samples/FILE"`` line puts that sample
file inline. ``mkdocs serve`` also watches the schema, the CLI and the device backends.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
GUIDE = ROOT / "docs" / "guide"
SCHEMA = ROOT / "mappings" / "schema.json"
CLI = ROOT / "puppet" / "cli.py"
MAPPING_PAGE = "reference/mapping.md"
COMMANDS_PAGE = "reference/commands.md"
FAPS_PAGE = "reference/faps.md"
FEATURE_POINTS_PAGE = "reference/feature-points.md"
REGENERATE = "python docs/hooks.py"
HELP_PYTHON = "with Python "  # the commands page says which: argparse lays out help a little differently by version
UNITS = {  # the FAP units (ISO/IEC 14496-2 Annex C) in words; their feature points are puppet.fap.units'
    "MNS0": "MNS, the mouth-nose separation / 1024", "MW0": "MW, the mouth width / 1024",
    "ES0": "ES, the eye separation / 1024", "ENS0": "ENS, the eye-nose separation / 1024",
    "IRISD0": "IRISD, the iris diameter / 1024", "AU": "AU, 1e-5 radians",
}
FDP_GROUPS = (("3.", "Eyes: corners and lid middles"), ("9.", "Nose"), ("2.1", "Chin"),
              ("8.", "Lips' outer edge (the vermilion border)"), ("2.", "Lips' inner edge (where they meet)"))
HELP_COLUMNS = "100"
INCLUDE = re.compile(r'^--8<-- "([^"]+)"$', re.M)
OPTIONS = re.compile(r"^<!-- url-options: ([a-z]+) -->$", re.M)
_CODE: dict = {"help": {}, "options": {}}  # what from_the_code() found, for on_page_markdown
BOUNDS = (("minimum", "≥"), ("exclusiveMinimum", ">"), ("maximum", "≤"), ("exclusiveMaximum", "<"))

# Runs in the child: every help text the CLI prints ({"": top level, command: its help}) and the
# URL options each device backend declares ({scheme: [options]}, null where it declares none).
_CHILD_SCRIPT = r"""
import contextlib, io, json, re, sys
from puppet.cli import main
from devices import BACKENDS, DeviceError, device_class

def help_of(argv):
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        try:
            main(argv)
        except SystemExit:
            pass
    return out.getvalue()

def options_of(scheme):
    try:
        declared = getattr(device_class(scheme, scheme), "OPTIONS", None)
    except DeviceError:
        return None
    return None if declared is None else sorted(declared)

top = help_of(["--help"])
found = re.search(r"^positional arguments:\s*\n\s*\{([^}]+)\}", top, re.M)
if found is None:
    sys.exit("puppet --help lists no subcommands in {a,b,...} form")
helps = {"": top}
for command in found.group(1).split(","):
    helps[command] = help_of([command, "--help"])
options = {scheme: options_of(scheme) for scheme in BACKENDS}

from puppet.face.default import default_face, load_default_rig
from puppet.face.landmarks import FDP_NEEDED, FDP_NEEDED_WHAT
from puppet.fap.table import faps
from puppet.fap.units import FAPU_DEFINITIONS

reach = load_default_rig().fap_reach
fapu = default_face().fapu

def end(value):
    return None if value in (float("inf"), float("-inf")) else round(float(value), 1)

rows = [{"number": f.number, "name": f.name, "unit": f.unit, "direction": f.direction,
         "bidirectional": f.bidirectional, "feature_points": list(f.feature_points), "description": f.description,
         "reach": [end(x) for x in reach[f.number]] if f.number in reach else None} for f in faps()]
units = {name: {"points": list(how[:2]), "size": fapu[name]} for name, how in FAPU_DEFINITIONS.items()}
needed = {f: FDP_NEEDED_WHAT[f] for f in FDP_NEEDED}
print(json.dumps({"help": helps, "options": options, "faps": rows, "units": units, "needed": needed}))
"""


def on_files(files, config):
    """Ask the code once per build for what the device pages show (the reference pages are files
    in the tree, written by ``generated_pages``)."""
    global _CODE
    _CODE = from_the_code()
    return files


def generated_pages(code: dict | None = None) -> dict[str, str]:
    """{path under docs/guide: text} of every page made from the code (module docstring)."""
    code = from_the_code() if code is None else code
    return {MAPPING_PAGE: mapping_reference(json.loads(SCHEMA.read_text("utf-8"))),
            COMMANDS_PAGE: command_reference(code["help"]),
            FAPS_PAGE: fap_glossary(code["faps"], code["units"]),
            FEATURE_POINTS_PAGE: feature_point_page(code["needed"])}


def write_pages() -> list[Path]:
    """Write the generated pages into docs/guide (``python docs/hooks.py``)."""
    written = []
    for name, text in generated_pages().items():
        path = GUIDE / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
        written.append(path)
    return written


def on_page_markdown(markdown: str, page, config, files) -> str:
    """Two markers, each on a line of its own: ``--8<-- "samples/x.ino"`` puts that file of the
    guide inline (a sample shown on a page and the file beside it are one), and
    ``<!-- url-options: SCHEME -->`` the list of URL options the backend declares (nothing when
    it declares none)."""
    def include(match: re.Match) -> str:
        path = Path(config["docs_dir"]) / match.group(1)
        if not path.is_file():
            raise FileNotFoundError(f"{page.file.src_uri}: included file {match.group(1)!r} does not exist")
        return path.read_text("utf-8").rstrip("\n")

    def options(match: re.Match) -> str:
        scheme = match.group(1)
        if scheme not in _CODE["options"]:
            raise KeyError(f"{page.file.src_uri}: no device backend for the scheme {scheme!r}")
        return url_options(scheme, _CODE["options"][scheme])
    return OPTIONS.sub(options, INCLUDE.sub(include, markdown))


def url_options(scheme: str, declared: list[str] | None) -> str:
    """The sentence listing a backend's declared URL options."""
    if declared is None:
        return ""
    names = ", ".join(f"`{o}`" for o in declared) or "none"
    return f"Every option a `{scheme}://` URL accepts (read from the backend's code): {names}."


def on_serve(server, config, builder):
    """``mkdocs serve`` rebuilds when the schema, the CLI or a device backend changes."""
    server.watch(str(SCHEMA))
    server.watch(str(CLI))
    server.watch(str(ROOT / "devices"))
    return server


# -- commands -------------------------------------------------------------------------------------

def from_the_code() -> dict:
    """``{"help": {"": top-level help, command: help}, "options": {scheme: [options] or None}}``,
    asked of this checkout's code in a child Python."""
    env = dict(os.environ, COLUMNS=HELP_COLUMNS, PYTHONPATH=os.pathsep.join(
        [str(ROOT)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]))
    done = subprocess.run([sys.executable, "-c", _CHILD_SCRIPT], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=120)
    if done.returncode != 0:
        raise RuntimeError(f"asking the code for its help and options failed ({done.returncode}): {done.stderr.strip()}")
    return json.loads(done.stdout)


def command_reference(helps: dict[str, str]) -> str:
    """The command reference page: the top-level help, then one section per subcommand."""
    commands = [c for c in helps if c]
    lines = ["# Command reference", "",
             f"Generated from the `puppet` command's own `--help` by `{REGENERATE}` ({HELP_PYTHON}"
             f"{sys.version_info.major}.{sys.version_info.minor}, whose argparse wrote it; a test checks it",
             "matches the code). Every command also runs as `python -m puppet.cli COMMAND` from a checkout.",
             "", " | ".join(f"[{c}](#puppet-{c})" for c in commands), "",
             "## puppet", "", "```text", helps[""].rstrip(), "```", ""]
    said = summaries(helps[""])
    for command in commands:
        lines += [f"## puppet {command}", ""] + ([_sentence(said[command]), ""] if command in said else [])
        lines += ["```text", helps[command].rstrip(), "```", ""]
    return "\n".join(lines)


def summaries(top_help: str) -> dict[str, str]:
    """Each subcommand's one-line help, read from the top-level help's list (wrapped lines joined)."""
    said: dict[str, str] = {}
    current = None
    for line in top_help.splitlines():
        entry = re.match(r"    ([a-z][\w-]*)(?:\s{2,}(\S.*))?$", line)
        if entry:
            current = entry.group(1)
            said[current] = entry.group(2) or ""
        elif current and re.match(r"\s{8,}\S", line):
            said[current] = f"{said[current]} {line.strip()}".strip()
        else:
            current = None
    return said


# -- FAPs and feature points --------------------------------------------------------------------

def fap_glossary(rows: list[dict], units: dict[str, dict]) -> str:
    """The FAP glossary: each FAP's number, name, what it moves, unit, positive direction and reach
    on the default face, from the code's FAP table and the default face's rig."""
    lines = ["# FAP glossary", "",
             f"Generated from the code's FAP table (`puppet.fap.table`) and the default face's rig by `{REGENERATE}`.",
             "A FAP (MPEG-4 facial animation parameter) moves one feature point, or turns the head or an eye;",
             "a mapping's `target` names it by name or number ([Mappings](../mappings.md)). Directions are the",
             "face's own: *left* is the face's left (the viewer's right), *forward* toward the viewer.", "",
             "Values are in the FAP's unit: a distance of the face's own divided by 1024, so one value moves",
             "every face alike. On the default face, in its mesh units:", ""]
    for name, unit in units.items():
        a, b = unit["points"]
        lines.append(f"- **{UNITS[name]}** (from feature point {a} to {b}): {unit['size']:.4g}")
    lines += [f"- **{UNITS['AU']}**: the unit of the head's and eyes' turns", "",
              "*Reach on the default face* is how far the FAP goes before a triangle of the default face would",
              "fold; the face stops there at pose time (a file keeps its values). A FAP another face is rigged",
              "for has that face's reach (`puppet rig` prints it). \"none\" is not limited.", "",
              "| # | name | what it moves | unit | positive | reach on the default face |",
              "|---|---|---|---|---|---|"]
    for row in rows:
        unit = UNITS[row["unit"]].split(",")[0] if row["unit"] else ""
        sense = row["direction"] if row["direction"] != "na" else ""
        if sense and not row["bidirectional"]:
            sense += " (one way)"
        points = f" (feature point {', '.join(row['feature_points'])})" if row["feature_points"] else ""
        lines.append(f"| {row['number']} | `{row['name']}` | {_cell(_sentence(row['description']))}{points} | {unit} "
                     f"| {sense} | {_reach(row['reach'], row['unit'])} |")
    return "\n".join(lines) + "\n"


def _reach(reach: list | None, unit: str | None) -> str:
    if unit is None:
        return ""
    if reach is None:
        return "none"
    low, high = (("none" if end is None else f"{end:g}") for end in reach)
    return f"{low} to {high}"


def _in_group(fdp: str, prefix: str) -> bool:
    """``prefix`` is a group ("8.") or one point ("2.1")."""
    return fdp.startswith(prefix) if prefix.endswith(".") else fdp == prefix


def feature_point_page(needed: dict[str, str]) -> str:
    """The feature points ``puppet rig`` needs, grouped, each with what it is, and their picture."""
    lines = ["# Feature points for puppet rig", "",
             f"Generated from `puppet.face.landmarks.FDP_NEEDED` by `{REGENERATE}`.",
             f"`puppet rig MESH --landmarks POINTS.json` needs these {len(needed)} MPEG-4 feature points, each the",
             "index of a vertex of the mesh (`{\"2.1\": 152, \"3.7\": 263, ...}`). The lip and lid loops run through",
             "them; every other feature point (brows, cheeks, jaw, ears, hairline, pupils) is placed from them as",
             "it sits on the default face, so leave those out unless you know where they are. *Left* is the face's",
             "own left: on a front view, the viewer's right. Give more points and they are used as given.", "",
             "![The feature points rig needs, on the default face: the whole face, and the mouth magnified]"
             "(../feature_points.png)", "",
             "The picture is the default face (`python tools/figures/feature_point_picture.py` draws it). The inner lip",
             "points of a closed mouth sit in pairs on the line where the lips meet (2.2 above 2.3, and so on).", ""]
    done: set[str] = set()
    for prefix, title in FDP_GROUPS:
        group = sorted((f for f in needed if f not in done and _in_group(f, prefix)),
                       key=lambda f: tuple(int(x) for x in f.split(".")))
        if not group:
            continue
        done |= set(group)
        lines += [f"## {title}", "", "| feature point | what it is |", "|---|---|"]
        lines += [f"| {f} | {needed[f]} |" for f in group] + [""]
    lines += ["## Other ways to give them", "",
              "- **The 68 iBUG points**: a JSON list of 68 vertex indices in the iBUG order (dlib, face-alignment)",
              "  gives them all. A file that holds that list under one key, as ICT-FaceKit's `vertex_indices.json`",
              "  does (`idx_to_landmark_verts`), is read from that key.",
              "- **Found**: without `--landmarks`, `puppet rig` finds them on renders of the mesh and writes them",
              "  to `landmarks.json`; `puppet pick-landmarks MESH --start landmarks.json -o points.json` shows them",
              "  on the mesh to move.",
              "- A missing point is named, with what it is, in one line; two points on one place are named with",
              "  what to move. See [Faces](../faces.md#landmarks-you-give)."]
    return "\n".join(lines) + "\n"


# -- the mapping schema ---------------------------------------------------------------------------

def mapping_reference(schema: dict) -> str:
    """The mapping reference page: the top-level keys, then each ``$defs`` entry's keys."""
    defs = schema.get("$defs", {})
    lines = ["# Mapping file reference", "",
             f"Generated from `mappings/schema.json` by `{REGENERATE}`. {schema.get('description', '')}",
             "", "Editors that read JSON Schema (VS Code with the YAML extension) check a mapping as you type",
             "when its first line is `# yaml-language-server: $schema=schema.json` (next to the schema)",
             "or names the schema's path. [Mappings](../mappings.md) explains how the parts work together.",
             "", "## Top level", "", "A mapping file is a YAML mapping with these keys:", ""]
    lines += _object_table(schema)
    for name, sub in defs.items():
        lines += ["", f"## {name}", ""]
        if sub.get("description"):
            lines += [_sentence(sub["description"]), ""]
        lines += _definition(sub)
    return "\n".join(lines) + "\n"


def _definition(schema: dict) -> list[str]:
    """One ``$defs`` entry: its key table (objects, variants chosen by ``type``) or its form."""
    lines: list[str] = []
    variants = _variants(schema)
    if "properties" in schema or schema.get("type") == "object":
        if schema.get("properties") and not variants:
            lines += _object_table(schema)
        elif variants:
            lines += [f"An object; `{variants[0][0]}` picks the variant ({_choices([v for _, v, _ in variants])}).", ""]
        for key, value, then in variants:
            lines += ["", f"### {key}: {value}", ""]
            own = {k: v for k, v in then.get("properties", {}).items() if k != key and isinstance(v, dict)}
            if own:
                lines += _object_table({"properties": own, "required": then.get("required", [])})
            else:
                lines += ["No other keys."]
        lines += _rules(schema)
    else:
        lines += [f"A value: {_type(schema)}."]
    return lines


def _object_table(schema: dict) -> list[str]:
    required = set(schema.get("required", []))
    rows = ["| key | value | required | default | description |", "|---|---|---|---|---|"]
    for key, sub in schema.get("properties", {}).items():
        if not isinstance(sub, dict):
            continue
        default = f"`{json.dumps(sub['default'])}`" if "default" in sub else ""
        rows.append(f"| `{key}` | {_cell(_type(sub))} | {'yes' if key in required else ''} | {default} "
                    f"| {_cell(sub.get('description', ''))} |")
    extra = schema.get("additionalProperties")
    if isinstance(extra, dict):
        names = schema.get("propertyNames", {}).get("pattern")
        what = f"any name matching `{names}`" if names else "any name"
        rows.append(f"| {what} | {_cell(_type(extra))} | | | |")
    elif extra is False:
        rows.append("")
        rows.append("No other keys are allowed.")
    return rows


def _variants(schema: dict) -> list[tuple[str, object, dict]]:
    """``(key, value, then)`` for each ``if key == value then ...`` of an ``allOf`` (curves, smoothing)."""
    out = []
    for part in schema.get("allOf", []):
        cond = part.get("if", {}).get("properties", {})
        if len(cond) == 1 and "then" in part:
            [(key, test)] = cond.items()
            if "const" in test:
                out.append((key, test["const"], part["then"]))
    return out


def _rules(schema: dict) -> list[str]:
    """The constraints that are not per key: one-of groups, conditional and dependent keys."""
    rules = []
    one_of = [s.get("required") for s in schema.get("oneOf", [])]
    if one_of and all(r and len(r) == 1 for r in one_of):
        rules.append(f"Exactly one of {', '.join(f'`{r[0]}`' for r in one_of)}.")
    for part in schema.get("allOf", []):
        cond, then = part.get("if", {}), part.get("then", {})
        if "anyOf" in cond and then.get("required"):
            keys = [r["required"][0] for r in cond["anyOf"] if len(r.get("required", [])) == 1]
            rules.append(f"With {', '.join(f'`{k}`' for k in keys)}: "
                         f"{', '.join(f'`{k}`' for k in then['required'])} is required.")
    for key, dep in schema.get("dependentSchemas", {}).items():
        if "required" in dep:
            fixed = {k: v["const"] for k, v in dep.get("properties", {}).items() if "const" in v}
            needs = ", ".join(f"`{k}: {fixed[k]}`" if k in fixed else f"`{k}`" for k in dep["required"])
            rules.append(f"`{key}` needs {needs}.")
        banned = [r["required"][0] for r in dep.get("not", {}).get("anyOf", []) if len(r.get("required", [])) == 1]
        if banned:
            rules.append(f"`{key}` cannot go with {', '.join(f'`{k}`' for k in banned)}.")
    return ["", "Rules:", ""] + [f"- {r}" for r in rules] if rules else []


def _type(schema: dict) -> str:
    """A value's form in words: a link to its definition, its allowed values, type and bounds."""
    if not isinstance(schema, dict) or schema == {}:
        return "anything"
    if "$ref" in schema:
        name = schema["$ref"].rsplit("/", 1)[-1]
        return f"[{name}](#{name.lower()})"
    if "const" in schema:
        return f"`{json.dumps(schema['const'])}`"
    if "enum" in schema:
        return _choices(schema["enum"])
    for key in ("anyOf", "oneOf"):
        if key in schema and all(isinstance(s, dict) for s in schema[key]):
            return " or ".join(_type(s) for s in schema[key])
    kind = schema.get("type")
    if isinstance(kind, list):
        text = " or ".join(kind)
    elif kind == "array":
        low, high = schema.get("minItems"), schema.get("maxItems")
        count = f" (exactly {low})" if low is not None and low == high else f" (at least {low})" if low else ""
        text = f"list{count} of {_type(schema.get('items', {}))}"
    elif kind == "object" and isinstance(schema.get("additionalProperties"), dict):
        names = schema.get("propertyNames", {}).get("pattern")
        text = (f"mapping of names{f' (matching `{names}`)' if names else ''} "
                f"to {_type(schema['additionalProperties'])}")
    else:
        text = kind or "anything"
    bounds = _bounds(schema)
    pattern = schema.get("pattern")
    return text + (f" {bounds}" if bounds else "") + (f" matching `{pattern}`" if pattern else "")


def _bounds(schema: dict) -> str:
    parts = [f"{op} {_number(schema[key])}" for key, op in BOUNDS if key in schema]
    return f"({', '.join(parts)})" if parts else ""


def _number(value: float) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def _choices(values: list) -> str:
    return "one of " + ", ".join(f"`{v}`" for v in values)


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _sentence(text: str) -> str:
    text = text.strip()
    return text[:1].upper() + text[1:] + ("" if text.endswith(".") else ".")


if __name__ == "__main__":
    for page in write_pages():
        print(page.relative_to(ROOT))
