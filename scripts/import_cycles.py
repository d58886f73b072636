#!/usr/bin/env python3
"""Find circles of imports between the .rs files of a Rust project, and print them.

Run from the workspace root (standard library only; it does not run cargo):
    python3 scripts/import_cycles.py [--quiet] [--dot FILE] [--verbose] [ROOT...]
ROOT is a crate source folder (default: every crates/*/src, and src, that exists). A
crate is named by its Cargo.toml ([lib] name, else [package] name, '-' made '_').

Imports (after comments, string and char literals are stripped; a file is all its text):
each leaf of a `use` (braces, self, super, crate, `as`, globs, `pub use`), and each path
`a::b` in code starting with crate/$crate/self/super, a crate of the set (relume_x::),
a child module, or a name brought in by `use`. `mod child;` is not an import. A glob
`use m::*` imports the file's identifiers that m defines or imports (`pub use m::*` is
also an edge to m itself); `use m::Enum::*` imports Enum.
Resolution: walk the path down the module tree by file layout (a/b.rs or a/b/mod.rs is
a::b; lib.rs/main.rs is the root; then inline `mod x {}`). If the next segment is an item
defined at that level (struct enum fn trait type const static union mod macro_rules), the
edge goes to that file; if the file only imports it (`pub use`, `as`, globs, and private
`use`, which child modules see through `super::`), follow that import, up to 16 deep. A
`use` of a module is an edge to its file only when no path through that name resolved.
std and external crates are ignored; an edge from a file to itself is dropped.
Output: each strongly connected component of 2+ files with its edges and the names used
(as defined in the target file), then `N import circles`; exit status 1 if N > 0. --dot FILE writes the whole file graph
(edges in circles red), --quiet prints only the summary, --verbose lists unresolved paths.
"""
import argparse
import glob
import os
import re
import sys
from collections import defaultdict

MAX_DEPTH = 16
KEYWORDS = set("""as async await break const continue crate dyn else enum extern false fn
    for if impl in let loop match mod move mut pub ref return self Self static struct super
    trait true type unsafe use where while union _""".split())
RAW_STR = re.compile(r'[bc]?r(#*)"')
TOKEN = re.compile(r"""
    (?P<modopen>\bmod\s+(?:r\#)?(?P<mname>[A-Za-z_]\w*)\s*\{)
  | (?P<macrodef>\bmacro_rules!\s*(?P<macname>[A-Za-z_]\w*))
  | (?P<item>\b(?:struct|enum|fn|trait|type|union|mod|const|static(?:\s+mut)?)\s+
        (?:r\#)?(?P<iname>[A-Za-z_]\w*))
  | (?P<use>(?P<pub>\bpub\s*(?:\([^)]*\))?\s*)?\buse\b(?!\s*<)(?P<utree>[^;]*);)
  | (?P<path>(?<![\w:$])\$?(?:r\#)?[A-Za-z_]\w*(?:\s*::\s*(?:r\#)?[A-Za-z_]\w*)+)
  | (?P<mcall>\b[A-Za-z_]\w*!\s*\{)
  | (?P<open>\{) | (?P<close>\})
""", re.X)
USE_TOKEN = re.compile(r"\$?(?:r#)?[A-Za-z_]\w*|::|[{}*,]")
IDENT = re.compile(r"\b[A-Za-z_]\w*\b")


def strip(s):
    """The source with comments removed and string/char literals emptied (newlines kept)."""
    out, i, n = [], 0, len(s)
    while i < n:
        c, j = s[i], i + 1
        after_ident = i > 0 and (s[i - 1].isalnum() or s[i - 1] == "_")
        raw = c in "bcr" and not after_ident and RAW_STR.match(s, i)
        if s.startswith("//", i):
            j = s.find("\n", i) % (n + 1)  # -1 (no newline) becomes n
        elif s.startswith("/*", i):  # block comments nest
            depth, j = 1, i + 2
            while j < n and depth:
                step = s[j:j + 2]
                depth += (step == "/*") - (step == "*/")
                j += 2 if step in ("/*", "*/") else 1
        elif raw:
            j = s.find('"' + raw.group(1), raw.end())
            j = n if j < 0 else j + 1 + len(raw.group(1))
        elif c == '"' or (c in "bc" and not after_ident and s.startswith('"', i + 1)):
            j = s.index('"', i) + 1
            while j < n and s[j] != '"':
                j += 2 if s[j] == "\\" else 1
            j += 1
        elif c == "'" and s.startswith("\\", i + 1):  # '\n', '\'', '\u{..}'
            j = s.find("'", i + 3) % (n + 1) + 1
        elif c == "'" and s.startswith("'", i + 2):  # 'a'; a lifetime 'a has no closing quote
            j = i + 3
        else:
            out.append(c)
            i += 1
            continue
        kept = "\n" * s.count("\n", i, j)
        out.append((" " if s[i] == "/" else '""' if s[i] != "'" else "' '") + kept)
        i = j
    return "".join(out)


def parse_use(text):
    """The leaves of a use tree: [(segments, alias)]; a glob leaf ends in '*'."""
    toks, leaves = USE_TOKEN.findall(text) + [";"], []

    def tree(pos, segs):  # one tree after the prefix segs; returns the position after it
        while toks[pos] == "::":
            pos += 1
        t = toks[pos]
        if t == "{":
            pos += 1
            while toks[pos] not in ("}", ";"):
                pos = tree(pos, segs)
                pos += toks[pos] == ","
            return pos + (toks[pos] == "}")
        if t == "*":
            leaves.append((segs + ("*",), None))
            return pos + 1
        if t in (",", "}", ";"):
            return pos
        name = t.removeprefix("r#")
        if toks[pos + 1] == "::":
            return tree(pos + 2, segs + (name,))
        alias, pos = name, pos + 1
        if toks[pos] == "as":
            alias, pos = toks[pos + 1], pos + 2
        if name != "self":
            leaves.append((segs + (name,), alias))
        elif segs:  # a::b::{self} is the module a::b
            leaves.append((segs, segs[-1] if alias == "self" else alias))
        return pos

    tree(0, ())
    return leaves


class File:
    def __init__(self, path, crate, modpath):
        self.path, self.crate, self.modpath = path, crate, modpath
        self.items = defaultdict(set)   # module path -> names defined at its top level
        self.scope = defaultdict(dict)  # module path -> alias -> (module path, use segments)
        self.globs = defaultdict(list)  # module path -> [(module path, segments before *)]
        self.inline = set()             # module paths of inline `mod x { }`
        self.uses = []                  # (module path, segments, alias, pub) per use leaf
        self.paths = []                 # (module path, segments) per path in code
        self.macros, self.idents = set(), set()

    def parse(self, text):
        stack = []  # ('mod', name) for inline modules, ('blk', '') or ('mac', '') otherwise

        def module():
            return self.modpath + tuple(name for kind, name in stack if kind == "mod")

        def module_level():  # not inside a fn, impl or trait body (macro braces don't count)
            return next((k == "mod" for k, _ in reversed(stack) if k != "mac"), True)

        for m in TOKEN.finditer(text):
            if m["modopen"]:
                if module_level():
                    self.items[module()].add(m["mname"])
                stack.append(("mod", m["mname"]))
                self.inline.add(module())
            elif m["macrodef"]:
                self.macros.add(m["macname"])
                self.items[module()].add(m["macname"])
            elif m["item"]:
                if module_level() and m["iname"] not in KEYWORDS:
                    self.items[module()].add(m["iname"])
            elif m["use"]:
                for segs, alias in parse_use(m["utree"]):
                    self.uses.append((module(), segs, alias, bool(m["pub"])))
                    if segs[-1] == "*":
                        self.globs[module()].append((module(), segs[:-1]))
                    elif alias != "_":
                        self.scope[module()][alias] = (module(), segs)
            elif m["path"]:
                segs = tuple(p.strip().removeprefix("r#") for p in m["path"].split("::"))
                self.paths.append((module(), segs))
            elif m["mcall"] or m["open"]:
                stack.append(("mac" if m["mcall"] else "blk", ""))
            elif m["close"] and stack:
                stack.pop()
        self.idents = set(IDENT.findall(text)) - KEYWORDS
        self.idents -= set().union(*self.items.values(), *self.scope.values())


class Crate:
    def __init__(self, name):
        self.name, self.modules, self.macros, self.dirs = name, {}, {}, set()


def cargo_name(root):
    """The crate name from ROOT/../Cargo.toml: [lib] name, else [package] name."""
    try:
        with open(os.path.join(root, "..", "Cargo.toml"), encoding="utf-8") as f:
            text = f.read()
    except OSError:
        text = ""
    names = {}
    for section, body in re.findall(r"^\[([^\]]+)\]([^\[]*)", text, re.M):
        m = re.search(r'^\s*name\s*=\s*"([^"]+)"', body, re.M)
        if m:
            names[section.strip()] = m.group(1)
    parent = os.path.basename(os.path.abspath(os.path.join(root, "..")))
    return (names.get("lib") or names.get("package") or parent).replace("-", "_")


class Graph:
    def __init__(self, roots):
        self.crates, self.files, self.memo, self.unresolved = {}, [], {}, []
        for root in roots:
            self.load(root)
        for f in self.files:
            for name in f.macros:  # #[macro_export] puts macros at the crate root
                f.crate.macros.setdefault(name, f)
        self.edges = {f: self.edges_of(f) for f in self.files}

    def load(self, root):
        texts = {}
        for p in sorted(glob.glob(os.path.join(root, "**", "*.rs"), recursive=True)):
            with open(p, encoding="utf-8", errors="replace") as fh:
                texts[p] = strip(fh.read())
        lib = self.crates[cargo_name(root)] = Crate(cargo_name(root))
        main, bin_crate, bin_mods = os.path.join(root, "main.rs"), None, set()
        if main in texts and os.path.join(root, "lib.rs") in texts:  # lib and bin share src/
            bin_crate = Crate(None)
            bin_mods = set(re.findall(r"\bmod\s+(?:r#)?(\w+)\s*;", texts[main]))
        for p, text in texts.items():
            parts = os.path.relpath(p, root)[:-3].replace(os.sep, "/").split("/")
            if parts[-1] == "mod" or parts in (["lib"], ["main"]):
                parts = parts[:-1]
            modpath, crate = tuple(parts), lib
            if bin_crate and (p == main or (modpath and modpath[0] in bin_mods)):
                crate = bin_crate
            if modpath in crate.modules:  # a.rs beside a/mod.rs, or main.rs without lib.rs
                continue
            f = crate.modules[modpath] = File(p, crate, modpath)
            crate.dirs.update(modpath[:k] for k in range(len(modpath)))  # a/ without a/mod.rs
            f.parse(text)
            self.files.append(f)

    def absolutize(self, f, M, segs, depth=0, globs=True):
        """(crate, path from its root) of a path written in module M of file f, or None."""
        cr, s0 = f.crate, segs[0]
        if depth > MAX_DEPTH:
            return None
        if s0 in ("crate", "$crate"):
            return cr, segs[1:]
        if s0 == "self":
            return cr, M + segs[1:]
        if s0 == "super":
            k = next(i for i, s in enumerate(segs + ("",)) if s != "super")
            return (cr, M[: len(M) - k] + segs[k:]) if k <= len(M) else None
        if M + (s0,) in cr.modules or M + (s0,) in f.inline or s0 in f.items[M]:
            return cr, M + segs
        if s0 in f.scope[M]:
            M2, s2 = f.scope[M][s0]
            a = self.absolutize(f, M2, s2, depth + 1)
            return a and (a[0], a[1] + segs[1:])
        if s0 in self.crates:
            return self.crates[s0], segs[1:]
        for gM, g in f.globs[M] if globs else ():  # a name brought in by `use m::*`
            a = g and self.absolutize(f, gM, g, depth + 1, globs=False)
            if a and self.resolve(a[0], a[1] + (s0,), depth + 1):
                return a[0], a[1] + segs
        return None

    @staticmethod
    def walk(cr, p):
        """(file, module path, segments consumed) of the deepest module that p names."""
        i = found = 0
        while i < len(p) and (p[: i + 1] in cr.modules or p[: i + 1] in cr.dirs):
            i += 1
            found = i if p[:i] in cr.modules else found
        i, f = found, cr.modules.get(p[:found])
        if f is None:
            return None
        P = p[:i]
        while i < len(p) and P + (p[i],) in f.inline:
            P, i = P + (p[i],), i + 1
        return f, P, i

    def resolve(self, cr, p, depth=0):
        """(defining file, 'mod' or 'item', its name) of an absolute path, or None."""
        key = (id(cr), p)
        if key in self.memo:
            return self.memo[key]
        self.memo[key] = None  # in progress: an import loop resolves to nothing
        w = self.walk(cr, p) if depth <= MAX_DEPTH else None
        result = None
        if w:
            f, P, i = w
            name = p[i] if i < len(p) else "*"
            if name == "*":
                result = (f, "mod", P[-1] if P else cr.name or "crate")
            elif name in f.items[P]:
                result = (f, "item", name)
            elif name in f.scope[P]:  # imported or re-exported here: follow it
                M2, s2 = f.scope[P][name]
                a = self.absolutize(f, M2, s2, depth + 1)
                result = a and self.resolve(a[0], a[1] + p[i + 1:], depth + 1)
            else:
                for gM, g in f.globs[P]:
                    a = g and self.absolutize(f, gM, g, depth + 1, globs=False)
                    result = a and self.resolve(a[0], a[1] + p[i:], depth + 1)
                    if result:
                        break
                if not result and i == 0 and name in cr.macros:
                    result = (cr.macros[name], "item", name)
        self.memo[key] = result or None
        return result or None

    def edges_of(self, f):
        out, used_aliases = defaultdict(set), set()  # target file -> names used

        def add(r, name=None):
            if r and r[0] is not f:
                out[r[0]].add(name or r[2])

        def lookup(M, segs):
            a = self.absolutize(f, M, segs)
            r = a and self.resolve(*a)
            if not r and (segs[0] in ("crate", "$crate", "self", "super") or segs[0] in self.crates):
                self.unresolved.append((f, "::".join(segs)))
            return a, r

        for M, segs in f.paths:
            a, r = lookup(M, segs)
            if r:
                add(r)
                if segs[0] in f.scope[M]:
                    used_aliases.add((M, segs[0]))
        for M, segs, alias, pub in f.uses:
            if segs[-1] != "*":
                a, r = lookup(M, segs)
                if r and not (r[1] == "mod" and (M, alias) in used_aliases):
                    add(r)
                continue
            a, r = lookup(M, segs[:-1]) if len(segs) > 1 else (None, None)
            if r and (r[1] == "item" or pub):  # use Enum::*, or pub use m::*
                add(r, segs[-2] + "::*")
            if r and r[1] == "mod":
                for ident in f.idents:
                    rr = self.resolve(a[0], a[1] + (ident,))
                    if rr and rr[1] == "item":
                        add(rr)
        return out


def sccs(nodes, succ):
    """Tarjan's strongly connected components, iteratively."""
    index, low, on_stack, stack, out = {}, {}, set(), [], []
    for root in nodes:
        if root in index:
            continue
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        work = [(root, iter(succ[root]))]
        while work:
            v, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(succ[w])))
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while not comp or comp[-1] != v:
                        comp.append(stack.pop())
                        on_stack.discard(comp[-1])
                    out.append(comp)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("roots", nargs="*", metavar="ROOT", help="crate source folders")
    ap.add_argument("--dot", metavar="FILE", help="write the whole file graph (Graphviz)")
    ap.add_argument("--quiet", action="store_true", help="print only the summary line")
    ap.add_argument("--verbose", action="store_true", help="list unresolved internal paths")
    args = ap.parse_args()
    roots = args.roots or sorted(glob.glob("crates/*/src")) + ["src"]
    roots = [r for r in roots if os.path.isdir(r)]
    if not roots:
        sys.exit("no crate source folders found")
    g = Graph(roots)
    show = {f: os.path.relpath(f.path) for f in g.files}
    succ = {show[f]: sorted(show[t] for t in g.edges[f]) for f in g.files}
    names = {(show[f], show[t]): sorted(n) for f in g.files for t, n in g.edges[f].items()}
    groups = sorted(sorted(c) for c in sccs(sorted(succ), succ) if len(c) > 1)
    in_circle = {}
    for k, group in enumerate(groups, 1):
        edges = [(a, b) for a in group for b in succ[a] if b in group]
        in_circle.update((e, k) for e in edges)
        if not args.quiet:
            print(f"circle {k}: {len(group)} files")
            print("".join(f"  {a}\n" for a in group), end="")
            print("".join(f"    {a} -> {b}: {', '.join(names[(a, b)])}\n" for a, b in edges))
    if args.verbose and not args.quiet:
        for f, path in sorted(g.unresolved, key=lambda u: (show[u[0]], u[1])):
            print(f"unresolved: {show[f]}: {path}")
    if args.dot:
        with open(args.dot, "w", encoding="utf-8") as out:
            out.write("digraph imports {\n  rankdir=LR;\n  node [shape=box, fontsize=10];\n")
            for a in sorted(succ):
                out.write(f'  "{a}";\n')
                for b in succ[a]:
                    label = ", ".join(names[(a, b)][:4]) + (", ..." if len(names[(a, b)]) > 4 else "")
                    red = ", color=red" if (a, b) in in_circle else ""
                    out.write(f'  "{a}" -> "{b}" [label="{label}"{red}];\n')
            out.write("}\n")
    print(f"{len(groups)} import circles")
    return 1 if groups else 0


if __name__ == "__main__":
    sys.exit(main())
