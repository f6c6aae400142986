"""Docstrings and comments that carry history or measured figures instead of a contract.

Walks every module of ``sonarslam.{slam,features,sonar,datasets}`` (the real folders ``slam/``,
``features/``, ``sonar/``, ``datasets/``), reads each docstring (module, class, function, and an
attribute's string after its assignment) with :mod:`ast` and each comment with one regular
expression that skips string literals, and lists the passages that match a history or
measured-figure marker; consecutive comment lines are read as one passage. Two pattern sets:

``STRONG``
    Markers that never belong in a contract ("issue 29", "session", "until the ... found",
    "~20x too small", "no longer", "ATE 97 m", a date or a commit). ``tests/test_docstrings.py``
    holds their count at zero.
``REVIEW``
    Wider candidates for a reader to judge ("measured", "was", "before", a figure with a unit in
    the same sentence as a dataset's name); many are legitimate ("measured minus predicted").

It also reports the docstrings' and comments' shares of the modules' non-blank lines
(informative only).

Usage::

    .venv/bin/python benchmarks/docstring_audit.py            # counts and the strong hits
    .venv/bin/python benchmarks/docstring_audit.py --review   # the review candidates too
"""

from __future__ import annotations

import argparse
import ast
import re
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LAYERS = ("slam", "features", "sonar", "datasets")

#: Markers of history or of a run's measured figure: none belongs in a docstring or a comment.
STRONG: dict[str, str] = {
    "issue": r"\bissues? #?\d+",
    "session": r"\bsessions?\b",
    "last stop": r"\blast stop\b",
    "until found": r"\buntil (the|a)\b[^.]{0,60}\b(found|showed|measured)\b",
    "benchmark found": r"\bbenchmarks? (found|showed|measured|gave)\b",
    "x too": r"\d+(\.\d+)?\s*[x×]\s*too\b",
    "no longer": r"\bno longer\b(?! than)|\bpreviously\b|\bformerly\b|\bused to (be|give|sit|live|hold)\b",
    "was the default": r"\b(it|this|that) was the [\w' ]{0,30}?\b(preset|default)\b",
    "for now": r"\bfor now\b|\bnot yet (the )?default\b|\buntil this version\b",
    "before a change": r"\bbefore (this|that|the) (change|refusal|move|merge|rework|version)\b",
    "ate figure": r"\b(ATE|RMSE)\s*(of\s*)?[~≈]?\d+(\.\d+)?\s*(m|cm)\b",
    "gave figure": r"\bgave (a |an )?[-−~≈]?\d",
    "dataset figure": (
        r"\b(marina|MTi)('s)?\b[^.;]{0,30}?(:|\bis\b|\breads\b|\bgave\b|\bgives\b)\s*"
        r"[-−~≈]?\d+(\.\d+)?\s*(m|deg|°|deg/s|°/s|%)(?![a-zA-Z_])"
    ),
    # an ISO date shown as a literal (``2024-05-02T10:31``) is an example, not history
    "date": r"(?<!``)\b(19|20)\d\d-[01]\d(-[0-3]\d)?\b",
    # "<another project> commit <hash>" cites the version of a source read; ours is history
    "commit": r"(?:^|[(,;:.]\s*|\b(?:at|in|since|before|after|until|from|of)\s)commit [0-9a-f]{7,40}\b",
}

#: Wider candidates: read each, keep the legitimate ones.
REVIEW: dict[str, str] = {
    "measured": r"\bmeasured\b",
    "was": r"\bwas\b|\bwere\b",
    "before": r"\bbefore\b",
    "dataset figure": (
        r"\b(marina|simulator|drawn worlds?|caves|MTi)\b[^.;]{0,80}?"
        r"[-−~≈]?\d+(\.\d+)?\s*(m|cm|deg|°|deg/s|°/s|%|Hz)(?![a-zA-Z_])"
    ),
    "figure then dataset": (
        r"[-−~≈]?\d+(\.\d+)?\s*(m|cm|deg|°|deg/s|°/s|%)(?![a-zA-Z_])[^.;]{0,60}?"
        r"\b(on|of|in) the (marina|simulator|drawn worlds?)\b"
    ),
}


@dataclass(frozen=True)
class Hit:
    """One marker in one docstring or comment."""

    path: str  #: relative to the repository
    line: int  #: 1-based line of the passage's start
    kind: str  #: "docstring" or "comment"
    marker: str  #: the pattern's name
    text: str  #: the matched passage with some context


def modules(root: Path = ROOT) -> list[Path]:
    """Every ``.py`` file of the four layers, sorted."""
    return sorted(p for layer in LAYERS for p in (root / layer).rglob("*.py"))


def _docstring(body: list[ast.stmt]) -> ast.Expr | None:
    """The docstring statement of a body, if it has one."""
    first = body[0] if body else None
    if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
        if isinstance(first.value.value, str):
            return first
    return None


def _string_statements(tree: ast.Module) -> list[ast.Expr]:
    """Docstrings of the module, its classes and functions (at any depth of statements), and
    attribute docstrings (a string statement right after an assignment)."""
    out: list[ast.Expr] = []
    stack: list[list[ast.stmt]] = [tree.body]
    while stack:
        body = stack.pop()
        doc = _docstring(body)
        if doc is not None:
            out.append(doc)
        for prev, cur in zip(body, body[1:], strict=False):
            if (
                isinstance(prev, ast.Assign | ast.AnnAssign)
                and isinstance(cur, ast.Expr)
                and isinstance(cur.value, ast.Constant)
                and isinstance(cur.value.value, str)
            ):
                out.append(cur)
        for stmt in body:  # only statements are walked: expressions hold no docstrings
            for field in ("body", "orelse", "finalbody", "handlers"):
                sub = getattr(stmt, field, None)
                if (
                    isinstance(sub, list)
                    and sub
                    and isinstance(sub[0], ast.stmt | ast.excepthandler)
                ):
                    stack.append(sub)  # type: ignore[arg-type]
            if isinstance(stmt, ast.Match):
                stack.extend(case.body for case in stmt.cases)
    return out


#: A string literal (skipped) or a comment (kept): one pass at C speed instead of :mod:`tokenize`
#: (``tests/test_docstrings.py`` checks that both find the same comments on the tree).
_STRING_OR_COMMENT = re.compile(
    r'"""(?:\\.|[^\\])*?"""'
    r"|'''(?:\\.|[^\\])*?'''"
    r'|"(?:\\.|[^"\\\n])*"'
    r"|'(?:\\.|[^'\\\n])*'"
    r"|#[^\n]*",
    re.DOTALL,
)


def comments(source: str) -> list[tuple[int, str]]:
    """``(line, text)`` of every comment of a module's source (``#`` and ``#:`` stripped)."""
    out = []
    line, pos = 1, 0
    for m in _STRING_OR_COMMENT.finditer(source):
        if m.group().startswith("#"):
            line += source.count("\n", pos, m.start())
            pos = m.start()
            out.append((line, m.group().lstrip("#:").strip()))
    return out


def passages(source: str) -> list[tuple[int, str, str]]:
    """``(line, kind, text)`` of every docstring and comment of a module's source."""
    out: list[tuple[int, str, str]] = []
    for node in _string_statements(ast.parse(source)):
        assert isinstance(node.value, ast.Constant)
        out.append((node.lineno, "docstring", str(node.value.value)))
    out += [(line, "comment", text) for line, text in comments(source)]
    return out


def _comment_blocks(items: list[tuple[int, str, str]]) -> list[tuple[int, str, str]]:
    """Consecutive comment lines joined into one passage (a sentence may span lines)."""
    out: list[tuple[int, str, str]] = []
    block: list[tuple[int, str]] = []
    for line, kind, text in sorted(items, key=lambda item: item[0]):
        if kind != "comment":
            out.append((line, kind, text))
            continue
        if block and line != block[-1][0] + 1:
            out.append((block[0][0], "comment", " ".join(t for _, t in block)))
            block = []
        block.append((line, text))
    if block:
        out.append((block[0][0], "comment", " ".join(t for _, t in block)))
    return out


def find(source: str, patterns: dict[str, str], path: str = "<string>") -> list[Hit]:
    """The markers of ``patterns`` in the docstrings and comments of ``source``."""
    hits = []
    for line, kind, text in _comment_blocks(passages(source)):
        flat = " ".join(text.split())
        for name, pattern in patterns.items():
            for m in re.finditer(pattern, flat, flags=re.IGNORECASE):
                lo, hi = max(0, m.start() - 50), min(len(flat), m.end() + 50)
                hits.append(Hit(path, line, kind, name, flat[lo:hi]))
    return hits


def audit(patterns: dict[str, str], root: Path = ROOT) -> list[Hit]:
    """The hits of ``patterns`` over every module of the four layers."""
    hits = []
    for p in modules(root):
        hits += find(p.read_text(), patterns, str(p.relative_to(root)))
    return hits


def docstring_share(root: Path = ROOT) -> tuple[int, int, int]:
    """``(docstring lines, comment-only lines, non-blank lines)`` over the four layers' modules."""
    doc = comment = total = 0
    for p in modules(root):
        source = p.read_text()
        total += sum(1 for ln in source.splitlines() if ln.strip())
        lines: set[int] = set()
        for node in ast.walk(ast.parse(source)):
            if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant):
                if isinstance(node.value.value, str) and node.end_lineno is not None:
                    lines.update(range(node.lineno, node.end_lineno + 1))
        doc += len(lines)
        comment += sum(1 for ln in source.splitlines() if ln.lstrip().startswith("#"))
    return doc, comment, total


# -- the public API's numpydoc ------------------------------------------------------------------

#: numpydoc's section names.
SECTIONS = (
    "Parameters",
    "Other Parameters",
    "Attributes",
    "Methods",
    "Returns",
    "Yields",
    "Receives",
    "Raises",
    "Warns",
    "Warnings",
    "See Also",
    "Notes",
    "References",
    "Examples",
)
_HEADER = re.compile(r"^([A-Z][\w ]*)\n(-+)[ \t]*$", re.MULTILINE)


def _sections(doc: str) -> tuple[dict[str, str], list[str]]:
    """A cleaned docstring's sections by name, and what is malformed in their headers."""
    heads = list(_HEADER.finditer(doc))
    out, problems = {}, []
    for i, m in enumerate(heads):
        name, rule = m.group(1), m.group(2)
        if name not in SECTIONS:
            problems.append(f"unknown section {name!r}")
        if len(rule) != len(name):
            problems.append(f"the underline of {name!r} is {len(rule)} long, not {len(name)}")
        out[name] = doc[m.end() : heads[i + 1].start() if i + 1 < len(heads) else len(doc)]
    return out, problems


def _entries(body: str) -> list[str]:
    """The names a Parameters or Attributes section documents (``a, b : type`` gives both)."""
    names = []
    for line in body.splitlines():
        if line.strip() and not line[0].isspace():
            names += [n.strip() for n in line.split(" : ")[0].split(",") if n.strip()]
    return names


def _signature(node: ast.FunctionDef | ast.AsyncFunctionDef) -> list[str]:
    a = node.args
    names = [x.arg for x in [*a.posonlyargs, *a.args, *a.kwonlyargs]]
    names += [f"*{a.vararg.arg}"] if a.vararg else []
    names += [f"**{a.kwarg.arg}"] if a.kwarg else []
    return [n for n in names if n not in ("self", "cls")]


def _check_callable(label: str, params: list[str], doc: str) -> list[str]:
    """A Parameters section lists exactly ``params``; without one, each is named in the text."""
    sections, problems = _sections(doc)
    problems = [f"{label}: {p}" for p in problems]
    if "Parameters" in sections:
        documented = {n.lstrip("*") for n in _entries(sections["Parameters"])}
        wanted = {p.lstrip("*") for p in params}
        if wanted - documented:
            problems.append(f"{label}: Parameters lacks {sorted(wanted - documented)}")
        if documented - wanted:
            problems.append(
                f"{label}: Parameters names {sorted(documented - wanted)}, not in the signature"
            )
    else:
        unnamed = [p for p in params if p.lstrip("*") not in doc]
        if unnamed:
            problems.append(f"{label}: {unnamed} not described (no Parameters section)")
    return problems


def _definition(module: str, name: str, root: Path) -> tuple[ast.AST, Path]:
    """The ``def`` or ``class`` of ``name`` in ``module`` (``sonarslam.x.y``), following one
    package's ``from .. import name``."""
    rel = Path(*module.split(".")[1:])
    path = root / rel / "__init__.py" if (root / rel).is_dir() else root / rel.with_suffix(".py")
    tree = ast.parse(path.read_text())
    for node in tree.body:
        if isinstance(node, ast.ClassDef | ast.FunctionDef) and node.name == name:
            return node, path
    for node in tree.body:
        if (
            isinstance(node, ast.ImportFrom)
            and node.module
            and name in [a.name for a in node.names]
        ):
            return _definition(node.module, name, root)
    raise LookupError(f"{name} is not defined in {path}")


def public_api_problems(root: Path = ROOT) -> list[str]:
    """What is malformed or missing in the numpydoc of ``sonarslam.__all__``'s names, read
    from the source (nothing is imported): section headers, every parameter of each function,
    of each public method and of a plain class's constructor documented, every field of a
    dataclass in its Attributes."""
    homes: dict[str, str] = {}
    for node in ast.parse((root / "sonarslam" / "__init__.py").read_text()).body:
        if isinstance(node, ast.AnnAssign) and getattr(node.target, "id", "") == "_HOMES":
            homes = ast.literal_eval(node.value)
    if not homes:
        raise LookupError("sonarslam/__init__.py has no _HOMES table")
    problems: list[str] = []
    for name, module in sorted(homes.items()):
        node, _ = _definition(module, name, root)
        assert isinstance(node, ast.ClassDef | ast.FunctionDef)
        doc = ast.get_docstring(node) or ""
        if not doc:
            problems.append(f"{name}: no docstring")
            continue
        if isinstance(node, ast.FunctionDef):
            problems += _check_callable(name, _signature(node), doc)
            continue
        sections, bad = _sections(doc)
        problems += [f"{name}: {p}" for p in bad]
        is_dataclass = any("dataclass" in ast.unparse(d) for d in node.decorator_list)
        is_protocol = any(ast.unparse(b) == "Protocol" for b in node.bases)
        if is_dataclass:
            fields = [
                s.target.id
                for s in node.body
                if isinstance(s, ast.AnnAssign)
                and isinstance(s.target, ast.Name)
                and not s.target.id.startswith("_")
                and "ClassVar" not in ast.unparse(s.annotation)
            ]
            documented = _entries(sections.get("Attributes", "")) + _entries(
                sections.get("Parameters", "")
            )
            missing = [f for f in fields if f not in documented]
            if missing:
                problems.append(f"{name}: fields not in Attributes {missing}")
        for item in node.body:
            if not isinstance(item, ast.FunctionDef):
                continue
            if item.name == "__init__" and not is_dataclass and not is_protocol:
                problems += _check_callable(f"{name}()", _signature(item), doc)
            elif not item.name.startswith("_"):
                item_doc = ast.get_docstring(item) or ""
                if not item_doc:
                    problems.append(f"{name}.{item.name}: no docstring")
                    continue
                is_property = any(ast.unparse(d).endswith("property") for d in item.decorator_list)
                params = [] if is_property else _signature(item)
                problems += _check_callable(f"{name}.{item.name}", params, item_doc)
    return problems


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--review", action="store_true", help="list the review candidates too")
    parser.add_argument("--root", type=Path, default=ROOT, help="a source tree (default: this one)")
    args = parser.parse_args(argv)
    strong = audit(STRONG, args.root)
    review = audit(REVIEW, args.root)
    for h in strong + (review if args.review else []):
        print(f"{h.path}:{h.line}: [{h.kind}, {h.marker}] ...{h.text}...")
    api = public_api_problems(args.root) if (args.root / "sonarslam").is_dir() else []
    for problem in api:
        print(f"public API: {problem}")
    doc, comment, total = docstring_share(args.root)
    print(
        f"strong markers: {len(strong)} in {len({(h.path, h.line) for h in strong})} passages;"
        f" review candidates: {len(review)} in {len({(h.path, h.line) for h in review})} passages;"
        f" of {total} non-blank lines, docstrings {doc} ({100 * doc / total:.1f} %),"
        f" comment lines {comment} ({100 * comment / total:.1f} %);"
        f" public API numpydoc problems: {len(api)}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
