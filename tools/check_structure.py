#!/usr/bin/env python3
"""Structure checks of the workspace's library code (stdlib only).

1. Import cycles between the files of each crate: every `use crate::a::b`, `use super::x`,
   `crate::a::f(...)` path in a file is an edge from that file's module to the module the path
   names; strongly connected components with more than one module are cycles.
2. Functions longer than MAX_LINES lines in `crates/*/src/**.rs`, found by brace matching.
3. The command line only parses: a `ValueEnum` in `crates/cli` whose variants are those of a
   library enum (the same names) duplicates the library's type (derive `clap::ValueEnum` on the
   library's enum behind its `cli` feature instead), and a command module in
   `crates/cli/src/commands` over MAX_COMMAND_LINES lines composes what a library should.
   Both have one list of known exceptions, CLI_EXCEPTIONS, to be emptied; an exception that no
   longer applies is a finding too, so that the list only shrinks. In the method commands
   (METHOD_COMMANDS), a flag's default written as a number literal repeats what the library's
   `Default` says (take it from there: `default_value_t = Overrides::default().iterations`);
   flags the library has no setting for are listed in OWN_DEFAULTS. A command-line enum that is
   translated into another enum (an `impl From<Arg> for …`, or match arms `Arg::A => Lib::B`)
   mirrors a library type under other names: parse the library's enum directly.
4. Upward imports: a file that names a module above it (its parent `mod.rs`, an ancestor, or
   the crate root, whose re-exports are for users) depends on what is built from it; shared
   items belong in a sibling module that both use. Documented exceptions would go in
   UPWARD_EXCEPTIONS (empty: every crate is clean).
5. Crate READMEs name files that exist: a backticked Rust file (`*.rs`), or a folder path
   through a `src/` (`crates/cli/src/commands/human/`), in `crates/*/README.md` must be found in
   that crate, as a path from the crate, its `src/` or the workspace root, or by its name
   anywhere in the crate. (Bare folder names are left alone: most are a run's outputs.)

Test code does not count: `#[cfg(test)]` items (the `mod tests` blocks) are cut out before both
checks, and `tests/`, `benches/` and `examples/` folders are not read.

Exits 1 and lists the findings when there are any. Before reading the workspace, the checks of
enum translations and README paths run on planted cases (`self_test`), so a check that stops
finding anything fails too.
"""

import re
import sys
from pathlib import Path

MAX_LINES = 200
MAX_COMMAND_LINES = 400

# Known findings of check 3 (the structure issue's second pass moves them into the libraries):
# `enum:<file>:<Name>` for a mirrored ValueEnum, `lines:<file>` for a long command module.
CLI_EXCEPTIONS: set[str] = set()

# The method commands, whose flags set a library's configuration (files or folders under
# crates/cli/src/commands), and their flags with a number default of the command's own (the
# demo scene's size, a dataset's downscale, a checkpoint interval the library does not keep).
METHOD_COMMANDS = [
    "surface/", "fusion.rs", "human/train.rs", "poses.rs", "study.rs", "train_args.rs",
]
OWN_DEFAULTS = {
    "surface/args.rs:match_downscale",
    "fusion.rs:width",
    "human/train.rs:checkpoint_every",
    "train_args.rs:checkpoint_every",
}
LITERAL_DEFAULT_RE = re.compile(r"default_value_t\s*=\s*-?[0-9][0-9_.eE+-]*\s*[,)\]]")
FIELD_RE = re.compile(r"\n\s*(?:pub(?:\([^)]*\))?\s+)?([a-z_][a-z0-9_]*)\s*:")

ROOT = Path(__file__).resolve().parent.parent


def strip_comments_and_strings(text):
    """The source with comments, string and char literals blanked (newlines kept), so that
    braces and paths are only counted in code."""
    out = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        nxt = text[i + 1] if i + 1 < n else ""
        if c == "/" and nxt == "/":
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
        elif c == "/" and nxt == "*":
            depth, j = 1, i + 2
            while j < n and depth:
                if text.startswith("/*", j):
                    depth, j = depth + 1, j + 2
                elif text.startswith("*/", j):
                    depth, j = depth - 1, j + 2
                else:
                    j += 1
            out.append(blank(text[i:j]))
            i = j
        elif c == "r" and re.match(r'r#*"', text[i:]) and not is_ident(text, i - 1):
            m = re.match(r'r(#*)"', text[i:])
            end = text.find('"' + m.group(1), i + len(m.group(0)))
            j = n if end < 0 else end + 1 + len(m.group(1))
            out.append(blank(text[i:j]))
            i = j
        elif c == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            out.append(blank(text[i : j + 1]))
            i = j + 1
        elif c == "'":
            m = re.match(r"'(\\.[^']*|[^\\'])'", text[i:])
            if m:  # a char literal; otherwise a lifetime
                out.append(" " * len(m.group(0)))
                i += len(m.group(0))
            else:
                out.append(c)
                i += 1
        else:
            out.append(c)
            i += 1
    return "".join(out)


def is_ident(text, i):
    return i >= 0 and (text[i].isalnum() or text[i] == "_")


def blank(s):
    return "".join("\n" if ch == "\n" else " " for ch in s)


def matching_brace(code, open_at):
    depth = 0
    for j in range(open_at, len(code)):
        if code[j] == "{":
            depth += 1
        elif code[j] == "}":
            depth -= 1
            if depth == 0:
                return j
    return len(code) - 1


def without_test_items(code):
    """`code` with every item under `#[cfg(test)]` blanked."""
    for m in reversed(list(re.finditer(r"#\[cfg\(test\)\]", code))):
        brace = code.find("{", m.end())
        semi = code.find(";", m.end())
        if brace < 0 or (0 <= semi < brace):
            end = semi
        else:
            end = matching_brace(code, brace)
        code = code[: m.start()] + blank(code[m.start() : end + 1]) + code[end + 1 :]
    return code


def source_files(crate):
    src = crate / "src"
    return sorted(p for p in src.rglob("*.rs")) if src.is_dir() else []


def module_of(crate, path):
    """The module path of a file, e.g. `['matching', 'refine']`; `[]` for the crate root."""
    rel = path.relative_to(crate / "src").with_suffix("")
    parts = list(rel.parts)
    if parts[-1] in ("lib", "main", "mod") and len(parts) >= 1:
        parts = parts[:-1]
    if path.parent == crate / "src" / "bin":
        return None  # each binary is its own crate
    return parts


def inline_modules(code):
    """Inline `mod name { ... }` blocks: (name, start, end) in the code."""
    found = []
    for m in re.finditer(r"\bmod\s+([A-Za-z_]\w*)\s*\{", code):
        end = matching_brace(code, m.end() - 1)
        found.append((m.group(1), m.start(), end))
    return found


PATH_RE = re.compile(r"\b(crate|super|self)((?:\s*::\s*[A-Za-z_]\w*)+)")
USE_RE = re.compile(r"\buse\s+(crate|super|self)\s*::([^;]*);")


def use_paths(use_tail):
    """The paths of one `use` tree after its root, e.g. `a::{b, c::d}` → a::b, a::c::d."""
    tail = re.sub(r"\s+", "", re.sub(r"\s+as\s+\w+", "", use_tail))
    out = []

    def walk(prefix, s):
        if s.startswith("{") and s.endswith("}"):
            depth, start = 0, 1
            for k, ch in enumerate(s):
                if ch == "{":
                    depth += 1
                elif ch == "}":
                    depth -= 1
                if (ch == "," and depth == 1) or (ch == "}" and depth == 0):
                    part = s[start:k]
                    if part:
                        walk(prefix, part)
                    start = k + 1
            return
        head, sep, rest = s.partition("::")
        if sep:
            walk(prefix + [head], rest)
        else:
            out.append(prefix + [s])

    walk([], tail)
    return out


def resolve(root, current, parts, modules):
    """The longest known module that a path starting at `root` names."""
    if root == "crate":
        base = []
    elif root == "self":
        base = list(current)
    else:
        base = list(current)
        parts = list(parts)
        if base:
            base = base[:-1]
        while parts and parts[0] == "super":
            parts = parts[1:]
            if base:
                base = base[:-1]
    full = base + [p for p in parts if p not in ("self", "*")]
    for k in range(len(full), -1, -1):
        if tuple(full[:k]) in modules:
            return tuple(full[:k])
    return None


def crate_modules(crate, keep=lambda path: True):
    """Each kept file's module with its path and code (comments, strings and test items
    blanked), and every module of the crate, inline ones included."""
    files = {}
    for path in source_files(crate):
        mod = module_of(crate, path)
        if mod is not None and keep(path):
            code = without_test_items(strip_comments_and_strings(path.read_text()))
            files[tuple(mod)] = (path, code)
    modules = set(files)
    # Inline modules (other than the cut-out tests) are modules of their own file.
    for mod, (_, code) in files.items():
        for inline, _, _ in inline_modules(code):
            modules.add(mod + (inline,))
    return files, modules


def module_paths(mod, code, modules):
    """`(here, target)` for every `use` and path in the code of file module `mod`: the module
    the path stands in (an inline module of the file, or `mod`) and the module it names."""
    spans = inline_modules(code)

    def owner(pos):
        for inline, s, e in spans:
            if s <= pos <= e:
                return mod + (inline,)
        return mod

    for m in USE_RE.finditer(code):
        here = owner(m.start())
        for parts in use_paths(m.group(2)):
            yield here, resolve(m.group(1), here, parts, modules)
    for m in PATH_RE.finditer(code):
        here = owner(m.start())
        parts = [p.strip() for p in m.group(2).split("::") if p.strip()]
        yield here, resolve(m.group(1), here, parts, modules)


def crate_graph(crate):
    files, modules = crate_modules(crate)
    edges = {m: set() for m in modules}
    for mod, (_, code) in files.items():
        for here, target in module_paths(mod, code, modules):
            add_edge(edges, here, target)
    return edges


def add_edge(edges, source, target):
    """An edge between two files' modules; a module's own children and parents are the tree,
    not an import."""
    if target is None or target == source:
        return
    if target == source[: len(target)] or source == target[: len(source)]:
        return
    edges[source].add(target)


def cycles(edges):
    """Tarjan's strongly connected components of more than one node."""
    index, low, stack, on_stack, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in edges.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    sys.setrecursionlimit(10000)
    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


FN_RE = re.compile(r"\bfn\s+([A-Za-z_]\w*)")


def long_functions(path):
    code = without_test_items(strip_comments_and_strings(path.read_text()))
    found = []
    for m in FN_RE.finditer(code):
        # The body is the first `{` after the signature, unless a `;` ends it first (a trait
        # method without a body).
        brace = code.find("{", m.end())
        semi = code.find(";", m.end())
        if brace < 0 or (0 <= semi < brace and not inside_parens(code, m.end(), semi)):
            continue
        end = matching_brace(code, brace)
        first = code.count("\n", 0, m.start()) + 1
        last = code.count("\n", 0, end) + 1
        if last - first + 1 > MAX_LINES:
            found.append((m.group(1), first, last - first + 1))
    return found


def inside_parens(code, start, pos):
    """Whether `pos` is inside brackets opened after `start` (a `;` in an array type)."""
    depth = 0
    for ch in code[start:pos]:
        if ch in "([<":
            depth += 1
        elif ch in ")]>":
            depth -= 1
    return depth > 0


def name(mod):
    return "::".join(mod) or "(root)"


def upward_imports(crate):
    """(file, ancestor module) of every path in a file's own code (not its inline modules',
    which may use their file) that names a module above the file. Test files are not read."""
    not_tests = lambda path: path.stem != "tests" and not path.stem.endswith("_tests")  # noqa: E731
    files, modules = crate_modules(crate, not_tests)
    found = set()
    for mod, (path, code) in files.items():
        for here, target in module_paths(mod, code, modules):
            if here == mod and target is not None and target != mod and target == mod[: len(target)]:
                found.add((path.relative_to(ROOT).as_posix(), name(target)))
    return found


# Files allowed an upward import (check 4), each with the reason beside it; none today.
UPWARD_EXCEPTIONS: set[str] = set()


VARIANT_RE = re.compile(r"^\s*([A-Z]\w*)\s*(?:[,({=]|$)", re.M)


def enum_variants(code, brace):
    """The variant names of the enum whose body opens at `brace` (attributes skipped)."""
    body = code[brace + 1 : matching_brace(code, brace)]
    depth, top = 0, []
    for ch in body:  # keep only the body's top level (no fields of struct-like variants)
        if ch in "{(":
            depth += 1
        elif ch in "})":
            depth -= 1
        elif depth == 0:
            top.append(ch)
            continue
        top.append(" " if ch != "\n" else ch)
    text = re.sub(r"#\[[^\]]*\]", " ", "".join(top))
    names = frozenset(VARIANT_RE.findall(text))
    fields = re.search(r"[A-Z]\w*\s*[({]", re.sub(r"#\[[^\]]*\]", " ", body))
    return names | {None} if fields else names


def enums(path, value_enum_only):
    """(name, variants) of the enums in a file (only `ValueEnum` derives if asked)."""
    code = without_test_items(strip_comments_and_strings(path.read_text()))
    found = []
    for m in re.finditer(r"\benum\s+([A-Za-z_]\w*)[^{;]*\{", code):
        before = code[max(0, m.start() - 300) : m.start()]
        derives = before[before.rfind("enum ") + 1 :] if "enum " in before else before
        if value_enum_only and "ValueEnum" not in derives:
            continue
        found.append((m.group(1), enum_variants(code, m.end() - 1)))
    return found


TRANSLATION_RE = r"\b{name}::\w+\s*(?:\{{[^}}]*\}}|\([^)]*\))?\s*=>\s*(?:Some\(\s*)?(?:\w+::)*[A-Z]\w*::[A-Z]\w*"


def translated(code, name):
    """Whether `code` turns enum `name`'s variants into another enum's variants."""
    if re.search(rf"\bimpl\s+From<\s*{name}\s*>", code):
        return True
    return re.search(TRANSLATION_RE.format(name=name), code) is not None


def translation_findings(files):
    """`{key: message}` for each enum of the command line (`files`: relative path → code, comments
    and strings stripped) whose variants some file translates into another enum's."""
    found = {}
    for rel, code in files.items():
        for m in re.finditer(r"\benum\s+([A-Za-z_]\w*)", code):
            name = m.group(1)
            for other, text in files.items():
                if translated(text, name):
                    found[f"enum:{rel}:{name}"] = (
                        f"crates/cli/src/commands/{rel}: enum {name} is translated into a "
                        f"library enum in {other}; parse the library's enum instead"
                    )
    return found


def literal_defaults(path):
    """The fields whose clap default is a number literal, test code left out."""
    code = without_test_items(path.read_text())
    fields = []
    for m in LITERAL_DEFAULT_RE.finditer(code):
        field = FIELD_RE.search(code, m.end())
        if field:
            fields.append(field.group(1))
    return fields


def cli_findings(crates):
    """Check 3's findings, as `CLI_EXCEPTIONS` keys with a message each."""
    library = {}
    for crate in crates:
        if crate.name == "cli":
            continue
        for path in source_files(crate):
            for name, variants in enums(path, False):
                # An enum whose variants carry data cannot be a ValueEnum: the CLI must build it.
                if len(variants) >= 2 and None not in variants:
                    library.setdefault(variants, f"{path.relative_to(ROOT)}: {name}")
    commands = ROOT / "crates" / "cli" / "src" / "commands"
    findings = {}
    own_seen = set()
    for path in sorted(commands.rglob("*.rs")):
        rel = path.relative_to(commands).as_posix()
        for name, variants in enums(path, True):
            if variants in library:
                findings[f"enum:{rel}:{name}"] = (
                    f"crates/cli/src/commands/{rel}: ValueEnum {name} mirrors {library[variants]}"
                )
        if any(rel == m or (m.endswith("/") and rel.startswith(m)) for m in METHOD_COMMANDS):
            for field in literal_defaults(path):
                key = f"{rel}:{field}"
                own_seen.add(key)
                if key not in OWN_DEFAULTS:
                    findings[f"default:{key}"] = (
                        f"crates/cli/src/commands/{rel}: --{field.replace('_', '-')} repeats a "
                        "number default; take it from the library's Default"
                    )
        lines = path.read_text().count("\n")
        if lines > MAX_COMMAND_LINES:
            findings[f"lines:{rel}"] = (
                f"crates/cli/src/commands/{rel} is {lines} lines (limit {MAX_COMMAND_LINES})"
            )
    files = {
        path.relative_to(commands).as_posix(): without_test_items(
            strip_comments_and_strings(path.read_text())
        )
        for path in sorted(commands.rglob("*.rs"))
    }
    findings.update(translation_findings(files))
    for key in sorted(OWN_DEFAULTS - own_seen):
        findings[f"own:{key}"] = f"OWN_DEFAULTS lists `{key}`, which has no number default: remove it"
    return findings


README_PATH_RE = re.compile(r"`([A-Za-z0-9_./-]+(?:\.rs|/))`")


def readme_findings(crate, text=None):
    """Backticked `.rs` files and `folder/`s of the crate's README (or of `text`) that the crate
    lacks."""
    readme = crate / "README.md"
    if text is None:
        if not readme.is_file():
            return []
        text = readme.read_text()
    missing = []
    for token in sorted(set(README_PATH_RE.findall(text))):
        want_dir = token.endswith("/")
        if "://" in token or token.startswith(".") or (want_dir and "src/" not in token):
            continue
        path = token.rstrip("/")
        candidates = [crate / path, crate / "src" / path, ROOT / path]
        exists = (lambda p: p.is_dir()) if want_dir else (lambda p: p.is_file())
        if any(exists(c) for c in candidates):
            continue
        base = Path(path).name
        if any(exists(p) for p in crate.rglob(base) if "target" not in p.parts):
            continue
        missing.append(f"{readme.relative_to(ROOT)} names `{token}`, which is not in the crate")
    return missing


def self_test():
    """The checks of translated enums and README paths, on planted cases; messages of failures."""
    planted = {
        "a.rs": "enum EdgeArg { Area, Product }\nfn f(a: EdgeArg) -> EdgeTest { match a { "
        "EdgeArg::Area => EdgeTest::TriangleArea, EdgeArg::Product => EdgeTest::DepthProduct } }",
        "b.rs": "enum KindArg { None, Paper }\nfn g(k: KindArg) { let _ = match k { "
        "KindArg::None => None, KindArg::Paper => Some(fewview_geom::C::Paper) }; }",
        "c.rs": "enum StartArg { A }\nimpl From<StartArg> for Start { fn from(_: StartArg) -> Self "
        "{ todo!() } }",
        "d.rs": "enum Shown { A, B }\nfn h(s: Shown) -> u8 { match s { Shown::A => 1, Shown::B => 2 } }",
    }
    found = translation_findings(planted)
    want = {"enum:a.rs:EdgeArg", "enum:b.rs:KindArg", "enum:c.rs:StartArg"}
    failures = []
    if set(found) != want:
        failures.append(f"translated enums: planted {sorted(want)}, found {sorted(found)}")
    cli = ROOT / "crates" / "cli"
    readme = "`src/main.rs` and `src/gone.rs`, `src/commands/` and `src/nowhere/`"
    missing = readme_findings(cli, readme)
    if len(missing) != 2 or not ("gone.rs" in missing[0] and "nowhere" in missing[1]):
        failures.append(f"README paths: planted gone.rs and nowhere/, found {missing}")
    return failures


def main():
    failures = self_test()
    for message in failures:
        print(f"check_structure.py's own check failed: {message}")
    if failures:
        return 1
    crates = sorted(p for p in (ROOT / "crates").iterdir() if (p / "Cargo.toml").is_file())
    problems = 0
    for crate in crates:
        for message in readme_findings(crate):
            problems += 1
            print(message)
    upward = set()
    for crate in crates:
        upward |= upward_imports(crate)
    for file, target in sorted(upward):
        if file not in UPWARD_EXCEPTIONS:
            problems += 1
            print(f"{file}: imports from {target}, a module above it")
    for file in sorted(UPWARD_EXCEPTIONS - {f for f, _ in upward}):
        problems += 1
        print(f"UPWARD_EXCEPTIONS lists `{file}`, which no longer imports upward: remove it")
    findings = cli_findings(crates)
    for key, message in sorted(findings.items()):
        if key not in CLI_EXCEPTIONS:
            problems += 1
            print(message)
    for key in sorted(CLI_EXCEPTIONS - findings.keys()):
        problems += 1
        print(f"CLI_EXCEPTIONS lists `{key}`, which no longer applies: remove it")
    for crate in crates:
        for comp in cycles(crate_graph(crate)):
            problems += 1
            print(f"import cycle in crates/{crate.name}: " + " <-> ".join(map(name, comp)))
    for crate in crates:
        for path in source_files(crate):
            for fn, line, length in long_functions(path):
                problems += 1
                rel = path.relative_to(ROOT)
                print(f"{rel}:{line}: fn {fn} is {length} lines (limit {MAX_LINES})")
    if problems:
        print(f"{problems} structure problem(s)")
        return 1
    print(
        "structure: no import cycles, no function over", MAX_LINES, "lines;",
        len(CLI_EXCEPTIONS), "known command-line exceptions",
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
