#!/usr/bin/env python3
"""Check the extension's use of Blender's Python API against the API stubs of a newer Blender.

Blender 5.1 and later run Python 3.13, for which no ``bpy`` module can be installed here, so the
Blender tests cannot run on them. This reads the stubs that fake-bpy-module publishes for the
newest Blender (``pip install fake-bpy-module-latest``; ``--stubs`` names their folder) and checks,
statically, what the add-on (``strnn_addon/`` and the package's ``__init__.py``) takes from the API:

- every ``bpy.types.X`` it names or subclasses exists, and every ``bl_*`` setting of its classes
  exists on the class it derives from;
- every menu it adds entries to exists (a menu kept for an older Blender, behind ``hasattr``, may be
  missing, as long as each entry still has a menu);
- every Blender operator it calls (``bpy.ops.M.O``) exists and takes the keywords it passes;
- every name it takes from ``bpy.props``, ``bpy.utils``, ``bpy.app``, ``bpy.path``,
  ``bpy_extras.anim_utils`` and ``mathutils`` exists;
- every icon it draws exists, and every ``context.X`` it reads is a member of ``Context``.

  python scripts/check_api_stubs.py --stubs DIR     # DIR: site-packages holding bpy-stubs/
Exit status 1 with one line per problem, 0 when everything is found.
"""

from __future__ import annotations

import argparse
import ast
import re
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
OUR_CLASS = re.compile(r"^STRNN_")
BLENDER_CLASS = re.compile(r"^[A-Z0-9]+_(MT|PT|OT|UL|HT|PIE)_\w+$")


def parse_stub(path: Path) -> ast.Module:
    """A .pyi file as an AST. The stubs use Python 3.12 syntax that 3.11 cannot parse: ``type X = ...``
    aliases become plain assignments, and type parameter lists of classes and functions are dropped."""
    text = re.sub(r"^(\s*)type (\w+)(\[[^\]]*\])? =", r"\1\2 =", path.read_text(), flags=re.M)
    text = re.sub(r"^(\s*)(class|def) (\w+)\[[^\]]*(\[[^\]]*\][^\]]*)*\]", r"\1\2 \3", text, flags=re.M)
    return ast.parse(text, filename=str(path))


class Stubs:
    """What the stubs define: classes of ``bpy.types`` with their members and bases, operators with
    their keywords, module-level names of the smaller modules, and the icon names."""

    def __init__(self, root: Path):
        self.root = root
        if not (root / "bpy-stubs").is_dir():
            raise SystemExit(f"error: no bpy-stubs/ in {root}: pip install fake-bpy-module-latest --target DIR")
        self.classes: dict[str, tuple[list[str], set[str]]] = {}
        # bpy.types holds the RNA classes and, once Blender has started, the menus and panels of its own
        # interface (bl_ui), which the add-on appends to
        ui = sorted((root / "bl_ui-stubs").rglob("*.pyi")) if (root / "bl_ui-stubs").is_dir() else []
        for path in [root / "bpy-stubs" / "types" / "__init__.pyi", *ui]:
            self._read_classes(path)
        self.icons = self._literal(root / "bpy-stubs" / "stub_internal" / "rna_enums" / "__init__.pyi", "IconItems")
        self.modules = {name: self._names(root / path) for name, path in {
            "bpy.props": "bpy-stubs/props/__init__.pyi", "bpy.utils": "bpy-stubs/utils/__init__.pyi",
            "bpy.app": "bpy-stubs/app/__init__.pyi", "bpy.path": "bpy-stubs/path/__init__.pyi",
            "anim_utils": "bpy_extras-stubs/anim_utils/__init__.pyi", "mathutils": "mathutils-stubs/__init__.pyi",
        }.items()}
        self.modules["bpy.app"] |= {p.name for p in (root / "bpy-stubs" / "app").iterdir() if p.is_dir()}
        self.modules["bpy.utils"] |= {p.name for p in (root / "bpy-stubs" / "utils").iterdir() if p.is_dir()}

    def _read_classes(self, path: Path) -> None:
        for node in parse_stub(path).body:
            if isinstance(node, ast.ClassDef):
                bases = [ast.unparse(b).split("[")[0].split(".")[-1] for b in node.bases]
                members = set()
                for item in node.body:
                    if isinstance(item, ast.AnnAssign) and isinstance(item.target, ast.Name):
                        members.add(item.target.id)
                    elif isinstance(item, ast.Assign):
                        members.update(t.id for t in item.targets if isinstance(t, ast.Name))
                    elif isinstance(item, ast.FunctionDef):
                        members.add(item.name)
                old = self.classes.get(node.name, ([], set()))
                self.classes[node.name] = (old[0] + bases, old[1] | members)

    @staticmethod
    def _names(path: Path) -> set[str]:
        names = set()
        for node in parse_stub(path).body:
            if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
                names.add(node.name)
            elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
                names.add(node.target.id)
            elif isinstance(node, ast.Assign):
                names.update(t.id for t in node.targets if isinstance(t, ast.Name))
        return names

    @staticmethod
    def _literal(path: Path, name: str) -> set[str]:
        for node in parse_stub(path).body:
            if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == name for t in node.targets):
                return {c.value for c in ast.walk(node.value) if isinstance(c, ast.Constant) and
                        isinstance(c.value, str)}
        raise SystemExit(f"error: {name} not found in {path}")

    def member(self, cls: str, name: str) -> bool:
        """Whether class ``cls`` or one of its bases defines ``name``."""
        seen, todo = set(), [cls]
        while todo:
            c = todo.pop()
            if c in seen or c not in self.classes:
                continue
            seen.add(c)
            bases, members = self.classes[c]
            if name in members:
                return True
            todo.extend(bases)
        return False

    def operator(self, module: str, op: str) -> set[str] | None:
        """The keywords of ``bpy.ops.module.op``, or None when there is no such operator."""
        path = self.root / "bpy-stubs" / "ops" / module / "__init__.pyi"
        if not path.is_file():
            return None
        for node in parse_stub(path).body:
            if isinstance(node, ast.ClassDef) and node.name == op:
                new = next((f for f in node.body if isinstance(f, ast.FunctionDef) and f.name == "__new__"), None)
                return set() if new is None else {a.arg for a in new.args.kwonlyargs}
            if isinstance(node, ast.FunctionDef) and node.name == op:
                return {a.arg for a in node.args.kwonlyargs}
        return None


def dotted(node: ast.AST) -> str:
    """``a.b.c`` of a Name / Attribute chain, else ''."""
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if isinstance(node, ast.Name):
        parts.append(node.id)
        return ".".join(reversed(parts))
    return ""


def check_file(path: Path, stubs: Stubs) -> list[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    rel = path.relative_to(REPO) if path.is_relative_to(REPO) else path
    problems = []

    def say(node, text):
        problems.append(f"{rel}:{getattr(node, 'lineno', 0)}: {text}")

    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute):
            name = dotted(node)
            parts = name.split(".")
            if name.startswith("bpy.types.") and len(parts) == 3 and parts[2] not in stubs.classes:
                say(node, f"bpy.types.{parts[2]} is not in the API")
            for module in ("bpy.props", "bpy.utils", "bpy.app", "bpy.path", "anim_utils", "mathutils"):
                prefix = module + "."
                if name.startswith(prefix) and name.count(".") == module.count(".") + 1:
                    if parts[-1] not in stubs.modules[module]:
                        say(node, f"{name} is not in the API")
            if len(parts) >= 2 and parts[-2] == "context" and parts[0] in ("context", "bpy", "C"):
                if not stubs.member("Context", parts[-1]) and parts[-1] not in ("strnn",):
                    say(node, f"Context has no member {parts[-1]!r}")
        if isinstance(node, ast.Call):
            name = dotted(node.func)
            parts = name.split(".")
            if name.startswith("bpy.ops.") and len(parts) == 4 and parts[2] != "strnn":
                keywords = stubs.operator(parts[2], parts[3])
                if keywords is None:
                    say(node, f"operator {name} is not in the API")
                else:
                    for kw in node.keywords:
                        if kw.arg is not None and kw.arg not in keywords:
                            say(node, f"{name} takes no keyword {kw.arg!r}")
            for kw in node.keywords:
                if kw.arg == "icon" and isinstance(kw.value, ast.Constant) and kw.value.value not in stubs.icons:
                    say(node, f"icon {kw.value.value!r} is not in the API")
        if isinstance(node, ast.ClassDef):
            bases = [dotted(b) for b in node.bases]
            blender = [b.split(".")[-1] for b in bases if b.startswith("bpy.types.")]
            for base in blender:
                for item in node.body:
                    targets = []
                    if isinstance(item, ast.Assign):
                        targets = [t.id for t in item.targets if isinstance(t, ast.Name)]
                    elif isinstance(item, ast.AnnAssign) and isinstance(item.target, ast.Name):
                        targets = [item.target.id]
                    for t in targets:
                        if t.startswith("bl_") and not stubs.member(base, t):
                            say(item, f"{base} has no setting {t!r}")
    return problems


def check_menus(stubs: Stubs) -> tuple[list[str], list[str]]:
    """(problems, notes) for the menus the add-on appends to (``ui.MENUS``: (menu, entry) pairs)."""
    tree = ast.parse((REPO / "strnn_addon" / "ui.py").read_text())
    pairs = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "MENUS" for t in node.targets):
            for elt in node.value.elts:
                menu, entry = elt.elts
                pairs.append((menu.value, entry.id))
    if not pairs:
        return ["strnn_addon/ui.py: MENUS not found"], []
    found: dict[str, list[str]] = {}
    notes = []
    for menu, entry in pairs:
        if menu in stubs.classes:
            found.setdefault(entry, []).append(menu)
        else:
            found.setdefault(entry, [])
            notes.append(f"menu {menu} is not in this API (skipped there: the add-on checks with hasattr)")
    problems = [f"strnn_addon/ui.py: {entry} has no menu in this API" for entry, menus in found.items() if not menus]
    return problems, notes


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--stubs", type=Path, required=True, help="folder holding bpy-stubs/ (fake-bpy-module)")
    args = p.parse_args(argv)
    stubs = Stubs(args.stubs)
    files = sorted((REPO / "strnn_addon").rglob("*.py")) + [REPO / "__init__.py"]
    problems = [line for f in files for line in check_file(f, stubs)]
    menu_problems, notes = check_menus(stubs)
    problems += menu_problems
    for note in notes:
        print(f"note: {note}")
    for line in problems:
        print(line)
    print(f"{len(files)} files checked against {len(stubs.classes)} API classes: "
          f"{'no problems' if not problems else f'{len(problems)} problem(s)'}")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
