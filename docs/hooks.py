"""MkDocs hooks: the parts of the guide that are made from the code at every build, so they
never drift from it.

* ``reference/mapping.md`` is written from ``mappings/schema.json`` (every key, its type, allowed
  values, default and description, section by section as the schema's ``$defs`` go);
* ``reference/commands.md`` is the ``puppet`` command's own ``--help`` and each subcommand's,
  the subcommands read from the top-level help's choices (nothing is listed by hand);
* on the device pages, a ``<!-- url-options: SCHEME -->`` line becomes the URL options that
  backend declares (``Device.OPTIONS``), when it declares them.

The code is asked in a child Python with the checkout first on its path, so the pages show this
checkout's code, not an installed snapshot.

The reference pages are added with ``File.generated`` (``on_files``): nothing is written into
the tracked tree. A ``--8<-- "samples/FILE"`` line puts that sample file inline. ``mkdocs
serve`` also watches the schema, the CLI and the device backends.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

from mkdocs.structure.files import File, Files

ROOT = Path(__file__).resolve().parent.parent
SCHEMA = ROOT / "mappings" / "schema.json"
CLI = ROOT / "puppet" / "cli.py"
MAPPING_PAGE = "reference/mapping.md"
COMMANDS_PAGE = "reference/commands.md"
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
print(json.dumps({"help": helps, "options": options}))
"""


def on_files(files: Files, config) -> Files:
    """Add the generated reference pages to the build (and keep what the code says for pages)."""
    global _CODE
    _CODE = from_the_code()
    files.append(File.generated(config, MAPPING_PAGE, content=mapping_reference(json.loads(SCHEMA.read_text("utf-8")))))
    files.append(File.generated(config, COMMANDS_PAGE, content=command_reference(_CODE["help"])))
    return files


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
             "Generated from the `puppet` command's own `--help` when this guide is built, so it always",
             "matches the code. Every command also runs as `python -m puppet.cli COMMAND` from a checkout.",
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


# -- the mapping schema ---------------------------------------------------------------------------

def mapping_reference(schema: dict) -> str:
    """The mapping reference page: the top-level keys, then each ``$defs`` entry's keys."""
    defs = schema.get("$defs", {})
    lines = ["# Mapping file reference", "",
             f"Generated from `mappings/schema.json` when this guide is built. {schema.get('description', '')}",
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
