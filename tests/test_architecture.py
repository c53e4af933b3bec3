"""docs/architecture.md and the import contract (pyproject.toml, ``[tool.importlinter]``) say
the same thing: the same layers in the same order, every top-level module of ``trajpref`` in
a layer, and each row of the table allowing exactly what the contract allows. ``lint-imports``
checks the code against the contract; the "for type hints only" clauses, which import-linter
can leave out only for all contracts at once, are checked here on the code itself.

Also: the helper of ``tests/conftest.py`` that stops the suite when the imported ``trajpref``
is another checkout's."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import grimp
import pytest
from conftest import trajpref_source_problem

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10: import-linter depends on tomli there
    import tomli as tomllib

REPO = Path(__file__).resolve().parents[1]
PACKAGE = REPO / "src" / "trajpref"
DOC = REPO / "docs" / "architecture.md"


@dataclass(frozen=True)
class Contract:
    """What ``[tool.importlinter]`` says about the top-level modules."""

    layers: list[set[str]]
    """Highest layer first; the modules of one layer are independent of each other."""
    forbidden: dict[str, set[str]]
    """Per module, the lower modules its ``forbidden`` contracts keep it from importing."""
    outside: set[str]
    """The layers contract's ``exhaustive_ignores``: modules deliberately in no layer."""
    exhaustive: bool
    """Whether ``lint-imports`` itself refuses a module in no layer."""

    def below(self, module: str) -> set[str]:
        """The modules of the layers below ``module``'s."""
        index = next(i for i, layer in enumerate(self.layers) if module in layer)
        return set().union(*self.layers[index + 1 :])

    def allowed(self, module: str) -> set[str]:
        """What ``module`` may import directly, by the contract."""
        return self.below(module) - self.forbidden.get(module, set())

    @property
    def layered(self) -> set[str]:
        return set().union(*self.layers)


def _top(name: str) -> str:
    """``trajpref.data.registry`` -> ``data``."""
    parts = name.split(".")
    assert parts[0] == "trajpref" and len(parts) > 1, name
    return parts[1]


def read_contract(pyproject: Path = REPO / "pyproject.toml") -> Contract:
    section = tomllib.loads(pyproject.read_text())["tool"]["importlinter"]
    assert section["root_package"] == "trajpref"
    layer_contracts = [c for c in section["contracts"] if c["type"] == "layers"]
    assert len(layer_contracts) == 1, "one layers contract is expected"
    layers_contract = layer_contracts[0]
    assert layers_contract["containers"] == ["trajpref"]
    layers = [{m.strip() for m in layer.split("|")} for layer in layers_contract["layers"]]
    forbidden: dict[str, set[str]] = {}
    for c in section["contracts"]:
        if c["type"] != "forbidden":
            continue
        # Direct imports only: a row says what a module may import itself.
        assert c.get("allow_indirect_imports") is True, c["name"]
        for source in c["source_modules"]:
            forbidden.setdefault(_top(source), set()).update(
                _top(m) for m in c["forbidden_modules"]
            )
    return Contract(
        layers=layers,
        forbidden=forbidden,
        outside=set(layers_contract.get("exhaustive_ignores", [])),
        exhaustive=bool(layers_contract.get("exhaustive")),
    )


def top_level_modules(package: Path = PACKAGE) -> set[str]:
    """The Python modules and packages directly under ``package`` (folders without Python,
    such as ``configs``, ``resources`` and ``zoo``, hold data and import nothing)."""
    found = set()
    for child in package.iterdir():
        if child.name == "__pycache__" or child.name.startswith("."):
            continue
        if child.is_file() and child.suffix == ".py" and child.name != "__init__.py":
            found.add(child.stem)
        elif child.is_dir() and any(child.rglob("*.py")):
            found.add(child.name)
    return found


def coverage_problems(found: set[str], contract: Contract) -> list[str]:
    """Modules in no layer (and not deliberately outside), and names that are no module."""
    problems = [
        f"trajpref.{m} is in no layer of [tool.importlinter]: put it in one (and a row in "
        "docs/architecture.md), or list it in exhaustive_ignores with the reason"
        for m in sorted(found - contract.layered - contract.outside)
    ]
    problems += [
        f"[tool.importlinter] names {m}, which is no module under src/trajpref"
        for m in sorted((contract.layered | contract.outside) - found)
    ]
    problems += [f"{m} is both in a layer and outside" for m in contract.layered & contract.outside]
    return problems


def read_diagram(text: str) -> list[set[str]]:
    """The layers of the diagram (the first code block), highest first. A layer's line starts
    at the block's margin; descriptions continue on indented lines, arrows on their own."""
    block = text.split("```", 2)[1]
    layers = []
    for line in block.splitlines()[1:]:
        if not line.strip() or line.strip() == "↓" or len(line) - len(line.lstrip()) > 2:
            continue
        names = re.split(r"\s{2,}", line.strip())[0]
        layers.append({m.strip() for m in names.split("|")})
    return layers


def read_table(text: str) -> dict[str, str]:
    """Module -> the table's "may import" cell (a row may name several modules)."""
    lines = text.splitlines()
    start = lines.index("| package | owns | may import |")
    rows: dict[str, str] = {}
    for line in lines[start + 2 :]:
        if not line.startswith("|"):
            break
        cells = line.strip().strip("|").split("|")
        for module in re.findall(r"`(\w+)`", cells[0]):
            assert module not in rows, f"{module} has two rows"
            rows[module] = cells[-1].strip()
    return rows


def parse_may_import(cell: str, module: str, contract: Contract) -> tuple[set[str], set[str]]:
    """A "may import" cell as (modules at runtime, modules for type hints only).

    The cell is ``nothing``, ``everything below``, or a comma-separated list of modules, where
    ``X and below`` adds the layers below X's; a note in parentheses may follow, and a note
    ``(X for type hints only)`` allows X under ``if TYPE_CHECKING:`` alone."""
    main, _, note = cell.partition(" (")
    main = main.replace("`", "").strip()
    hinted = set()
    match = re.fullmatch(r"`?(\w+)`? for type hints only\)", note.strip())
    if match:
        hinted.add(match.group(1))
    if main == "nothing":
        return set(), hinted
    if main == "everything below":
        return contract.below(module), hinted
    runtime = set()
    for item in main.split(", "):
        name, and_below, rest = item.partition(" and below")
        assert not rest, f"{module}: cannot read {item!r} in {cell!r}"
        assert name in contract.layered, f"{module}: {name!r} in {cell!r} is no layered module"
        runtime.add(name)
        if and_below:
            runtime |= contract.below(name)
    return runtime, hinted


def row_problems(rows: dict[str, str], contract: Contract) -> list[str]:
    """Rows whose "may import" differs from what the contract allows."""
    problems = []
    for module, cell in sorted(rows.items()):
        runtime, hinted = parse_may_import(cell, module, contract)
        table = runtime | hinted
        allowed = contract.allowed(module)
        if table != allowed:
            problems.append(
                f"{module}: the table allows {sorted(table)}, the contract {sorted(allowed)}"
                f" (only in the table: {sorted(table - allowed)};"
                f" only in the contract: {sorted(allowed - table)})"
            )
        if runtime & hinted:
            problems.append(f"{module}: {sorted(runtime & hinted)} both at runtime and hinted")
    return problems


def runtime_imports(graph: grimp.ImportGraph, source: str, target: str) -> list[str]:
    """``source``'s direct imports of ``target`` (both top-level, with their descendants)
    that are in ``graph``, as ``importer:line -> imported``."""
    found = []
    sources = {f"trajpref.{source}"} | graph.find_descendants(f"trajpref.{source}")
    for importer in sorted(sources & graph.modules):
        for imported in sorted(graph.find_modules_directly_imported_by(importer)):
            if imported == f"trajpref.{target}" or imported.startswith(f"trajpref.{target}."):
                for detail in graph.get_import_details(importer=importer, imported=imported):
                    found.append(f"{importer}:{detail['line_number']} -> {imported}")
    return found


@pytest.fixture(scope="module")
def contract() -> Contract:
    return read_contract()


@pytest.fixture(scope="module")
def doc() -> str:
    return DOC.read_text()


def test_every_top_level_module_is_in_a_layer(contract):
    assert contract.exhaustive, "the layers contract must be exhaustive"
    assert coverage_problems(top_level_modules(), contract) == []


def test_a_new_module_in_no_layer_is_reported(contract):
    """The check of the test above, given a module that the contract does not name."""
    problems = coverage_problems(top_level_modules() | {"plugins"}, contract)
    assert len(problems) == 1 and "trajpref.plugins is in no layer" in problems[0]
    outside = Contract(contract.layers, contract.forbidden, contract.outside | {"plugins"}, True)
    assert coverage_problems(top_level_modules() | {"plugins"}, outside) == []


def test_the_diagram_has_the_contracts_layers_in_order(contract, doc):
    assert read_diagram(doc) == contract.layers


def test_the_table_names_the_contracts_modules(contract, doc):
    assert set(read_table(doc)) == contract.layered


def test_each_row_allows_what_the_contract_allows(contract, doc):
    assert row_problems(read_table(doc), contract) == []


def test_a_row_narrower_than_the_contract_is_reported(contract, doc):
    """Without its forbidden contract, ``adapt`` may import ``rl`` (walkthrough 62: the row
    said "evaluation and below" while ``adapt -> rl`` passed ``lint-imports``)."""
    forbidden = {m: s for m, s in contract.forbidden.items() if m != "adapt"}
    looser = Contract(contract.layers, forbidden, contract.outside, True)
    problems = row_problems(read_table(doc), looser)
    assert len(problems) == 1 and problems[0].startswith("adapt:"), problems
    assert "only in the contract: ['rl']" in problems[0]


def test_type_hint_only_imports_stay_under_type_checking(contract, doc):
    graph = grimp.build_graph("trajpref", exclude_type_checking_imports=True, cache_dir=None)
    found = []
    for module, cell in sorted(read_table(doc).items()):
        for hinted in sorted(parse_may_import(cell, module, contract)[1]):
            found += runtime_imports(graph, module, hinted)
    assert found == [], "imports allowed for type hints only, made at runtime"


def test_a_runtime_import_of_a_hinted_module_is_found():
    graph = grimp.ImportGraph()
    for name in ("trajpref", "trajpref.diffusion", "trajpref.config", "trajpref.errors"):
        graph.add_module(name)
    graph.add_import(
        importer="trajpref.diffusion.schedule",
        imported="trajpref.config",
        line_number=7,
        line_contents="from trajpref.config import DiffusionConfig",
    )
    graph.add_import(
        importer="trajpref.diffusion",
        imported="trajpref.errors",
        line_number=3,
        line_contents="from trajpref.errors import ConfigError",
    )
    assert runtime_imports(graph, "diffusion", "config") == [
        "trajpref.diffusion.schedule:7 -> trajpref.config"
    ]
    assert runtime_imports(graph, "diffusion", "io") == []


def test_parse_may_import(contract):
    assert parse_may_import("nothing (torch only)", "metrics", contract) == (set(), set())
    runtime, hinted = parse_may_import("errors (config for type hints only)", "diffusion", contract)
    assert (runtime, hinted) == ({"errors"}, {"config"})
    runtime, _ = parse_may_import("evaluation and below", "adapt", contract)
    assert "evaluation" in runtime and "rl" not in runtime and "errors" in runtime
    with pytest.raises(AssertionError, match="no layered module"):
        parse_may_import("plugins", "adapt", contract)


# The copy check of tests/conftest.py ------------------------------------------------------


def test_source_check_accepts_this_checkouts_package(tmp_path):
    (tmp_path / "src" / "trajpref").mkdir(parents=True)
    origin = tmp_path / "src" / "trajpref" / "__init__.py"
    assert trajpref_source_problem(str(origin), tmp_path) is None
    link = tmp_path.parent / f"{tmp_path.name}-link"
    link.symlink_to(tmp_path)
    assert trajpref_source_problem(str(origin), link) is None


def test_source_check_names_another_checkout(tmp_path):
    other = tmp_path / "main" / "src" / "trajpref" / "__init__.py"
    copy = tmp_path / "copy"
    problem = trajpref_source_problem(str(other), copy)
    assert problem is not None
    assert str(other.parent) in problem and str(copy / "src" / "trajpref") in problem
    assert "make install" in problem and "PYTHONPATH=src" in problem


def test_source_check_names_a_missing_package(tmp_path):
    problem = trajpref_source_problem(None, tmp_path)
    assert problem is not None and "not importable" in problem and "PYTHONPATH=src" in problem
