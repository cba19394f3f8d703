"""Collect real HID report descriptors from public projects into tests/data/hid, one hex file each.

The descriptors are the bytes devices send to the host; other projects recorded them for their own
tests and docs. This script reads them out of local copies of those projects (it takes no code):

- hid-tools (https://gitlab.freedesktop.org/libevdev/hid-tools, GPL-2.0): ``rdesc="05 01 ..."``
  arguments and ``report_descriptor = [0x05, 0x01, ...]`` lists in ``tests_kernel/*.py``,
  ``hidtools/device/*.py`` and ``tests/test_cli_decode.py`` (``R:`` lines). The Linux kernel's HID
  selftests (``tools/testing/selftests/hid/tests``, GPL-2.0) are the same files, so a checkout of
  either works (``--hid-tools DIR`` for each; later ones add only what is new).
- xpadneo (https://github.com/atar-axis/xpadneo, GPL-3.0): the hex dumps in
  ``docs/descriptors/**/*.md`` (plain rows, ``xxd`` rows, or ``xpadneo hid-desc:`` log rows).

A descriptor is named after its source and device (``hidtools_test_multitouch_3m_0596_0500``,
``xpadneo_xb1s_linux``); bytes seen before under another name are written once, and the names
that share them are printed. Usage::

    python tools/builders/collect_hid_descriptors.py --hid-tools ~/src/hid-tools --xpadneo ~/src/xpadneo \\
        -o tests/data/hid
"""

from __future__ import annotations

import argparse
import ast
import re
from pathlib import Path

HEX_ROW = re.compile(r"^(?:xpadneo hid-desc: )?(?:[0-9a-fA-F]{8}: )?((?:[0-9a-fA-F]{2} )*[0-9a-fA-F]{2})(?:\s{2,}.*)?$")
NAME = re.compile(r"[^A-Za-z0-9]+")


def _clean(text: str) -> str:
    return NAME.sub("_", text).strip("_")


def _hex_bytes(text: str) -> bytes | None:
    words = text.split()
    if len(words) < 8 or not all(re.fullmatch(r"[0-9a-fA-F]{2}", w) for w in words):
        return None
    return bytes(int(w, 16) for w in words)


def _int_list(node: ast.AST) -> bytes | None:
    if not isinstance(node, ast.List) or len(node.elts) < 8:
        return None
    if not all(isinstance(e, ast.Constant) and type(e.value) is int and 0 <= e.value < 256 for e in node.elts):
        return None
    return bytes(e.value for e in node.elts)


def from_python(path: Path, prefix: str) -> list[tuple[str, bytes]]:
    """Descriptors in one Python file: ``rdesc=`` hex strings (named by the device name beside
    them) and lists of byte values assigned to a name (named by the enclosing class or the name)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    found: list[tuple[str, bytes]] = []

    def visit(node: ast.AST, owner: str) -> None:
        if isinstance(node, ast.ClassDef):
            owner = node.name
        if isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name):
            target = node.targets[0].id
            data = _int_list(node.value) if target in ("report_descriptor", "rdesc") or not owner else None
            if data is not None and not owner.startswith("Bad"):  # BadReportDescriptorMouse: garbage on purpose
                found.append((owner or target, data))
        if isinstance(node, ast.Call):
            for keyword in node.keywords:
                if keyword.arg == "rdesc" and isinstance(keyword.value, ast.Constant) \
                        and isinstance(keyword.value.value, str):
                    data = _hex_bytes(keyword.value.value)
                    if data is not None:
                        found.append((_device_name(node) or owner, data))
        for child in ast.iter_child_nodes(node):
            visit(child, owner)

    visit(tree, "")
    for text in (n.value for n in ast.walk(tree) if isinstance(n, ast.Constant) and isinstance(n.value, str)):
        for line in text.splitlines():  # hid-recorder's "R: <length> <bytes>" lines
            if line.startswith("R: "):
                data = _hex_bytes(line[3:].split(" ", 1)[1]) if " " in line[3:] else None
                name = re.search(r"^N: (.+)$", text, re.M)
                if data is not None and name:
                    found.append((name.group(1), data))
    return [(f"{prefix}_{path.stem}_{_clean(name)}", data) for name, data in found]


def _device_name(call: ast.Call) -> str | None:
    for arg in call.args:
        if isinstance(arg, ast.Constant) and isinstance(arg.value, str) and arg.value.startswith("uhid test "):
            return arg.value[len("uhid test "):]
    return None


def from_markdown(path: Path, prefix: str) -> list[tuple[str, bytes]]:
    """Each fenced block of hex rows in an xpadneo descriptor page."""
    found, rows, inside = [], [], False
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            if inside and rows:
                data = _hex_bytes(" ".join(rows))
                if data is not None and len(data) >= 20 and data[0] in (0x05, 0x06):  # not a report's bytes
                    found.append(data)
            inside, rows = not inside, []
            continue
        match = HEX_ROW.match(line.strip()) if inside else None
        if match:
            rows.append(match.group(1))
    stem = f"{prefix}_{_clean(path.stem)}"
    return [(stem if i == 0 else f"{stem}_{i + 1}", data) for i, data in enumerate(found)]


def collect(hid_tools: list[Path], xpadneo: list[Path]) -> list[tuple[str, bytes]]:
    found = []
    for root in xpadneo:
        for path in sorted((root / "docs" / "descriptors").rglob("*.md")):
            found += from_markdown(path, "xpadneo")
    for root in hid_tools:
        files = [*sorted(root.glob("tests_kernel/*.py")), *sorted(root.glob("hidtools/device/*.py")),
                 *sorted(root.glob("tests/test_cli_decode.py")), *sorted(root.glob("test_*.py")),
                 *sorted(root.glob("descriptors_*.py"))]
        for path in files:
            found += from_python(path, "hidtools")
    return found


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--hid-tools", type=Path, action="append", default=[],
                        help="a hid-tools checkout, or the kernel's tools/testing/selftests/hid/tests")
    parser.add_argument("--xpadneo", type=Path, action="append", default=[], help="an xpadneo checkout")
    parser.add_argument("-o", "--out", type=Path, required=True)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    written: dict[bytes, str] = {}
    for name, data in collect(args.hid_tools, args.xpadneo):
        if data in written:
            print(f"{name}: the same bytes as {written[data]}")
            continue
        while name in written.values():
            name += "_2"
        written[data] = name
        (args.out / f"{name}.hex").write_text(data.hex(" ") + "\n")
    print(f"{len(written)} descriptors written to {args.out}")


if __name__ == "__main__":
    main()
