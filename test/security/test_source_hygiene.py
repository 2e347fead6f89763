"""No code path in src/ that turns untrusted input into code execution.

Parsed with ``ast`` rather than grepped, so comments and docstrings do not trigger it and
aliases (``from yaml import load``) do not escape it. Forbidden: pickle-family modules, eval /
exec / compile, yaml loaders other than the safe ones, ``shell=True``, os.system/os.popen,
``numpy.load(allow_pickle=True)``, ``pandas.read_pickle``. The checker is tested on known-bad
snippets first, so that a clean result means something.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from conftest import REPO

SRC = REPO / "src"
PICKLE_MODULES = {"pickle", "cPickle", "_pickle", "dill", "cloudpickle", "shelve", "marshal",
                  "jsonpickle"}
SAFE_YAML_LOADERS = {"SafeLoader", "CSafeLoader", "BaseLoader", "CBaseLoader"}
UNSAFE_YAML = {"load", "load_all", "unsafe_load", "unsafe_load_all", "full_load",
               "full_load_all"}
UNSAFE_YAML_CLASSES = {"Loader", "UnsafeLoader", "FullLoader", "CLoader", "CUnsafeLoader",
                       "CFullLoader"}


def _dotted(node: ast.AST) -> str:
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if isinstance(node, ast.Name):
        parts.append(node.id)
    return ".".join(reversed(parts))


def _is_true(node: ast.AST) -> bool:
    return isinstance(node, ast.Constant) and node.value is True


def findings(source: str, name: str = "<snippet>") -> list[str]:
    """Every forbidden construct in ``source`` as ``name:line: what``."""
    tree = ast.parse(source, name)
    found = []
    yaml_names = {"yaml"}  # names bound to the yaml module
    from_yaml: dict[str, str] = {}  # local name -> yaml attribute

    def report(node, what):
        found.append(f"{name}:{node.lineno}: {what}")

    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] in PICKLE_MODULES:
                    report(node, f"import {alias.name}")
                if alias.name == "yaml":
                    yaml_names.add(alias.asname or "yaml")
        elif isinstance(node, ast.ImportFrom) and node.module:
            if node.module.split(".")[0] in PICKLE_MODULES:
                report(node, f"from {node.module} import ...")
            if node.module == "yaml":
                for alias in node.names:
                    from_yaml[alias.asname or alias.name] = alias.name
                    if alias.name in UNSAFE_YAML_CLASSES:
                        report(node, f"from yaml import {alias.name}")
        elif isinstance(node, ast.Attribute) and _dotted(node.value) in yaml_names \
                and node.attr in UNSAFE_YAML_CLASSES:
            report(node, f"yaml.{node.attr}")
        elif isinstance(node, ast.Call):
            func = _dotted(node.func)
            head, _, attr = func.rpartition(".")
            keywords = {k.arg: k.value for k in node.keywords}
            if func in ("eval", "exec", "compile", "__import__"):
                report(node, f"{func}()")
            elif (head in yaml_names and attr in UNSAFE_YAML) or (
                    not head and from_yaml.get(func) in UNSAFE_YAML):
                loader = keywords.get("Loader", node.args[1] if len(node.args) > 1 else None)
                if loader is None or _dotted(loader).split(".")[-1] not in SAFE_YAML_LOADERS:
                    report(node, f"{func}() without a safe Loader")
            elif func in ("os.system", "os.popen", "pandas.read_pickle", "pd.read_pickle"):
                report(node, f"{func}()")
            if "shell" in keywords and not (isinstance(keywords["shell"], ast.Constant)
                                            and keywords["shell"].value is False):
                report(node, f"{func}(shell=...)")
            if attr == "load" and head in ("np", "numpy") and _is_true(
                    keywords.get("allow_pickle", ast.Constant(False))):
                report(node, f"{func}(allow_pickle=True)")
    return found


@pytest.mark.parametrize("snippet", [
    "import pickle",
    "import pickle as p",
    "from dill import loads",
    "x = eval('1')",
    "exec('x = 1')",
    "import yaml\nyaml.load(s)",
    "import yaml\nyaml.load(s, Loader=yaml.Loader)",
    "import yaml as y\ny.load(s, y.FullLoader)",
    "import yaml\nyaml.unsafe_load(s)",
    "from yaml import load\nload(s)",
    "from yaml import UnsafeLoader",
    "import subprocess\nsubprocess.run('ls', shell=True)",
    "import subprocess\nsubprocess.Popen(cmd, shell=flag)",
    "import os\nos.system('ls')",
    "import numpy as np\nnp.load(f, allow_pickle=True)",
    "import pandas as pd\npd.read_pickle(f)",
])
def test_checker_catches_known_bad_code(snippet):
    assert findings(snippet), snippet


@pytest.mark.parametrize("snippet", [
    "import yaml\nyaml.safe_load(s)",
    "import yaml\nyaml.load(s, Loader=yaml.SafeLoader)",
    "import yaml\nyaml.load(s, yaml.CSafeLoader)",
    "import yaml\nloader = yaml.SafeLoader(s)",
    "import subprocess\nsubprocess.run(['ls'], shell=False)",
    "import numpy as np\nnp.load(f)",
    "'''eval(x) and pickle in a docstring'''",
    "# os.system('x') in a comment",
    "model.eval_rms(x)",
])
def test_checker_passes_safe_code(snippet):
    assert findings(snippet) == []


def _python_files():
    return sorted(p for p in SRC.rglob("*.py")
                  if not any(part in ("build", "install", ".venv") for part in p.parts))


def test_source_tree_has_no_code_execution_paths():
    files = _python_files()
    assert len(files) > 10  # the tree is there
    problems = [f for path in files
                for f in findings(path.read_text(encoding="utf-8"), str(path.relative_to(REPO)))]
    assert problems == []
