#!/usr/bin/env python3
"""Checks the layering of lensopt's modules: a module may include only its own headers and those of
the modules below it. Usage: tools/check-layering.py [source-tree]   (default: this script's tree)

It reads every #include "lensopt/<module>/..." (public header) and "<module>/..." (a module's
internal header under src/) in include/lensopt/<module>/ and src/<module>/, and prints
"file:line: <module> includes <other>/...: upward (<module> may include: ...)" for each include the
table below does not allow. Exit status 1 when there is one, 0 otherwise.

The table is the layering of CONTRIBUTING.md ("Modules") and of the CMake module libraries
(CMakeLists.txt, lensopt_add_module): each module names the modules it builds on directly; it may
include those and, transitively, everything below them. A module listed before another never
depends on it, so the table has no cycle by construction (checked below).
"""
import pathlib
import re
import sys

# module: the modules it builds on directly (each listed earlier).
LAYERS = {
    "core": [],
    "glass": ["core"],
    "lens": ["glass"],
    "paraxial": ["lens"],
    "trace": ["paraxial"],
    "analysis": ["trace"],
    "formats": ["analysis"],
    "optimize": ["analysis"],
    "render": ["analysis"],
    "plot": ["render"],
    "tolerance": ["optimize", "plot"],
    "search": ["formats", "optimize"],
    "detection": ["render"],
    "joint": ["optimize", "render", "detection"],
    "cli": ["formats", "tolerance", "search", "joint", "plot"],
}

INCLUDE = re.compile(r'^\s*#\s*include\s*"(?:lensopt/)?([a-z_]+)/')


def allowed_modules():
    allowed = {}
    for module, below in LAYERS.items():
        for lower in below:
            if lower not in allowed:
                raise SystemExit(f"check-layering: {module} builds on {lower}, listed after it")
        allowed[module] = {module}.union(*(allowed[lower] for lower in below))
    return allowed


def main():
    root = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else pathlib.Path(__file__).parent.parent)
    allowed = allowed_modules()
    errors = []
    folders = [(root / "include" / "lensopt", "public"), (root / "src", "source")]
    for base, kind in folders:
        if not base.is_dir():
            raise SystemExit(f"check-layering: no folder {base}")
        for folder in sorted(p for p in base.iterdir() if p.is_dir()):
            module = folder.name
            if module not in LAYERS:
                errors.append(f"{folder}: module '{module}' is not in the layering table of "
                              f"tools/check-layering.py (and CMakeLists.txt): add it there")
                continue
            for path in sorted(folder.rglob("*")):
                if path.suffix not in (".h", ".cpp", ".inl") or not path.is_file():
                    continue
                text = path.read_text(encoding="utf-8", errors="replace")
                for number, line in enumerate(text.splitlines(), 1):
                    match = INCLUDE.match(line)
                    if not match:
                        continue
                    target = match.group(1)
                    if target not in LAYERS:
                        continue  # a third-party folder (toml++/, ceres/, ...), not a module
                    if target not in allowed[module]:
                        below = ", ".join(m for m in LAYERS if m in allowed[module])
                        header = line.split('"')[1]
                        errors.append(f"{path.relative_to(root)}:{number}: {module} includes "
                                      f"{header}: upward ({module} may include: {below})")
    for error in errors:
        print(error, file=sys.stderr)
    if errors:
        print(f"check-layering: {len(errors)} include(s) against the module layering",
              file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
