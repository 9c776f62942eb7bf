# The add-on's import graph, read from its sources (no Blender needed): every package imports only from the packages
# before it, blender/ <- objects/ <- io/, tools/ <- ui/, with engine/ on blender/ and objects/; there is no import
# circle; and no module imports another of the add-on inside a function (the way a circle is dodged), except cli.py,
# which runs as a script and imports the add-on once it has registered it.
#   python3 check_addon_imports.py [--print]     (--print: the graph, one module and what it imports per line)
import ast
import os
import sys
import unittest

ADDON = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "addon", "raysplats")
# What each package may import from (the top-level modules, "", are shared infrastructure).
ALLOWED = {
    "": {""},
    "blender": {"", "blender"},
    "objects": {"", "blender", "objects"},
    "io": {"", "blender", "objects", "io"},
    "tools": {"", "blender", "objects", "tools"},
    "ui": {"", "blender", "objects", "io", "tools", "ui"},
    "engine": {"", "blender", "objects", "engine"},
}
SCRIPTS = {"cli"}  # run with --python, import the add-on by name inside functions


def modules():
    """{dotted name relative to the add-on ("io.format_table", "engine" for a package's __init__): path}."""
    found = {}
    for folder, _, files in os.walk(ADDON):
        for name in files:
            if name.endswith(".py"):
                relative = os.path.relpath(os.path.join(folder, name), ADDON)[:-3].replace(os.sep, ".")
                found[relative.removesuffix(".__init__") if relative != "__init__" else ""] = os.path.join(folder,
                                                                                                           name)
    return found


def imports_of(name, path, known):
    """[(imported module, line, inside a function)] of the add-on's modules that module `name` imports."""
    package = name if os.path.basename(path) == "__init__.py" else name.rpartition(".")[0]
    tree = ast.parse(open(path, encoding="utf-8").read(), path)
    function_lines = {node.lineno for function in ast.walk(tree)
                      if isinstance(function, (ast.FunctionDef, ast.AsyncFunctionDef))
                      for node in ast.walk(function) if node is not function and hasattr(node, "lineno")}
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.ImportFrom):
            continue
        if node.level:
            parts = package.split(".") if package else []
            parts = parts[:len(parts) - (node.level - 1)] if node.level > 1 else parts
            base = ".".join(parts + ([node.module] if node.module else []))
        elif node.module and (node.module == "raysplats" or node.module.startswith("raysplats.")):
            base = node.module[len("raysplats"):].lstrip(".")
        else:
            continue
        for alias in node.names:
            target = f"{base}.{alias.name}".lstrip(".")
            target = target if target in known else base
            if target in known and target not in (name, ""):  # ("" : `from . import _native`, the built module)
                found.append((target, node.lineno, node.lineno in function_lines))
    return found


def graph():
    known = modules()
    return {name: imports_of(name, path, known) for name, path in sorted(known.items())}


def package_of(name):
    return name.split(".")[0] if "." in name else ("" if name not in ALLOWED else name)


def cycles(edges):
    """The import circles among module-level imports (each as a list of modules), or []."""
    found, state = [], {}

    def visit(node, stack):
        state[node] = 1
        for target in edges.get(node, ()):
            if state.get(target) == 1:
                found.append(stack[stack.index(target):] + [target])
            elif state.get(target) is None:
                visit(target, stack + [target])
        state[node] = 2

    for node in edges:
        if state.get(node) is None:
            visit(node, [node])
    return found


class AddonImports(unittest.TestCase):
    def setUp(self):
        self.graph = graph()

    def test_there_is_no_import_circle(self):
        # The package's __init__ imports every module to register them: it is the root, not part of the graph.
        edges = {name: {target for target, _, _ in imports if target != ""}
                 for name, imports in self.graph.items() if name != ""}
        self.assertEqual(cycles(edges), [])

    def test_packages_import_only_the_packages_before_them(self):
        for name, imports in self.graph.items():
            if name == "" or name in SCRIPTS:
                continue
            for target, line, _ in imports:
                allowed = ALLOWED[package_of(name)]
                with self.subTest(module=name, imports=target):
                    self.assertIn(package_of(target), allowed, f"{name} (line {line}) imports {target}")

    def test_no_import_inside_a_function(self):
        for name, imports in self.graph.items():
            if name in SCRIPTS:
                continue
            for target, line, inside in imports:
                with self.subTest(module=name, imports=target):
                    self.assertFalse(inside, f"{name} imports {target} inside a function (line {line})")

    def test_the_checks_see_the_add_on(self):
        # (A wrong path would make every check above pass on nothing.)
        self.assertIn("objects.splat_object", self.graph)
        self.assertIn(("objects.polygon_mesh", True), {(t, True) for t, _, _ in self.graph["objects.splat_object"]})


if __name__ == "__main__":
    if "--print" in sys.argv:
        for module, imports in graph().items():
            print(f"{module or '__init__'}: {', '.join(sorted({target or '__init__' for target, _, _ in imports}))}")
        sys.exit(0)
    unittest.main()
