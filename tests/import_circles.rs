//! No two files of any crate in the workspace import each other, directly or round a longer
//! circle. One test walks every member that the workspace's `Cargo.toml` lists, with no way for a
//! crate to opt out: `cargo test -p kitchen-r --test import_circles`.
//!
//! What counts as an import. The module tree is read from the crate root through its `mod`
//! declarations (`#[path]` included). A file depends on another when its code names an item
//! defined there: through a `use` whose name the file's own code then uses, through a path in code
//! or in an attribute (`crate::…`, `super::…`, `self::…`, a child module, or a name bound to a
//! module by a `use`), or through a glob `use` from which it uses a name.
//!
//! The rule for parents and children: **a re-export is a pass-through, not a dependency.** A name
//! is followed through every `use` that re-exports it to the file that defines it, and a `use`
//! whose name the file's own code never mentions adds no edge. So a parent module file that only
//! declares (`mod x;`) and re-exports (`pub(crate) use x::Y;`) its children is no circle with
//! them, even while a child names the parent's path (`crate::service::Caller` is an edge to the
//! file that defines `Caller`). A parent whose own code uses a child's item while the child uses
//! an item the parent defines is a circle like any other: the shared item belongs in a third file.
//!
//! Tests are not part of the graph: items under `#[cfg(test)]` (test modules, test-only `use`
//! lines) are skipped, so a test may drive any module. Comments and string literals are skipped.
//! The reading is textual (a tokenizer, no macro expansion): a name it cannot find in a crate
//! module is taken to live in that module's file.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};

#[derive(Clone, Debug, PartialEq)]
enum Tok {
    Ident(String),
    Str(String),
    Punct(char),
    PathSep,
    Other,
}

#[derive(Clone, Debug)]
struct Token {
    tok: Tok,
    line: usize,
}

fn tokenize(text: &str) -> Vec<Token> {
    let c: Vec<char> = text.chars().collect();
    let at = |i: usize| c.get(i).copied().unwrap_or('\0');
    let mut out = Vec::new();
    let mut line = 1;
    let mut i = 0;
    while i < c.len() {
        let ch = c[i];
        let start_line = line;
        let ident_start = |x: char| x.is_alphabetic() || x == '_';
        if ch == '\n' {
            line += 1;
            i += 1;
        } else if ch.is_whitespace() {
            i += 1;
        } else if ch == '/' && at(i + 1) == '/' {
            while i < c.len() && c[i] != '\n' {
                i += 1;
            }
        } else if ch == '/' && at(i + 1) == '*' {
            let mut depth = 0;
            while i < c.len() {
                if c[i] == '/' && at(i + 1) == '*' {
                    depth += 1;
                    i += 2;
                } else if c[i] == '*' && at(i + 1) == '/' {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    if c[i] == '\n' {
                        line += 1;
                    }
                    i += 1;
                }
            }
        } else if let Some((hashes, open)) = raw_string_start(&c, i) {
            // r"…", r#"…"#, br"…": runs to the quote followed by as many hashes.
            let mut j = open + 1;
            let mut s = String::new();
            while j < c.len() && !(c[j] == '"' && (1..=hashes).all(|k| at(j + k) == '#')) {
                if c[j] == '\n' {
                    line += 1;
                }
                s.push(c[j]);
                j += 1;
            }
            out.push(Token {
                tok: Tok::Str(s),
                line: start_line,
            });
            i = j + 1 + hashes;
        } else if ch == '"' || (ch == 'b' && at(i + 1) == '"') {
            let mut j = if ch == 'b' { i + 2 } else { i + 1 };
            let mut s = String::new();
            while j < c.len() && c[j] != '"' {
                if c[j] == '\\' {
                    s.push(c[j]);
                    j += 1;
                }
                if at(j) == '\n' {
                    line += 1;
                }
                s.push(at(j));
                j += 1;
            }
            out.push(Token {
                tok: Tok::Str(s),
                line: start_line,
            });
            i = j + 1;
        } else if ch == '\'' || (ch == 'b' && at(i + 1) == '\'') {
            let q = if ch == 'b' { i + 1 } else { i };
            if at(q + 1) == '\\' {
                // An escaped char literal: '\n', '\'', '\u{…}'.
                let mut j = q + 3;
                while j < c.len() && c[j] != '\'' {
                    j += 1;
                }
                i = j + 1;
            } else if at(q + 2) == '\'' {
                i = q + 3;
            } else {
                // A lifetime or label.
                i = q + 1;
                while i < c.len() && (c[i].is_alphanumeric() || c[i] == '_') {
                    i += 1;
                }
            }
            out.push(Token {
                tok: Tok::Other,
                line: start_line,
            });
        } else if ident_start(ch) || (ch == 'r' && at(i + 1) == '#' && ident_start(at(i + 2))) {
            if ch == 'r' && at(i + 1) == '#' {
                i += 2;
            }
            let from = i;
            while i < c.len() && (c[i].is_alphanumeric() || c[i] == '_') {
                i += 1;
            }
            out.push(Token {
                tok: Tok::Ident(c[from..i].iter().collect()),
                line,
            });
        } else if ch.is_ascii_digit() {
            while i < c.len()
                && (c[i].is_alphanumeric() || c[i] == '_' || (c[i] == '.' && at(i + 1).is_ascii_digit()))
            {
                i += 1;
            }
            out.push(Token {
                tok: Tok::Other,
                line,
            });
        } else if ch == ':' && at(i + 1) == ':' {
            out.push(Token {
                tok: Tok::PathSep,
                line,
            });
            i += 2;
        } else {
            out.push(Token {
                tok: Tok::Punct(ch),
                line,
            });
            i += 1;
        }
    }
    out
}

/// `(hashes, index of the opening quote)` when a raw string starts at `i`.
fn raw_string_start(c: &[char], i: usize) -> Option<(usize, usize)> {
    let mut j = i;
    if c.get(j) == Some(&'b') {
        j += 1;
    }
    if c.get(j) != Some(&'r') {
        return None;
    }
    if i > 0 && (c[i - 1].is_alphanumeric() || c[i - 1] == '_') {
        return None;
    }
    j += 1;
    let mut hashes = 0;
    while c.get(j) == Some(&'#') {
        hashes += 1;
        j += 1;
    }
    (c.get(j) == Some(&'"')).then_some((hashes, j))
}

type ModPath = Vec<String>;

/// One `use` binding: `name` (or `*` for a glob) for `path`, as written, in module `module`.
#[derive(Debug)]
struct Use {
    module: ModPath,
    name: String,
    path: Vec<String>,
    line: usize,
}

/// What one file declares and names.
#[derive(Debug, Default)]
struct Parsed {
    /// `mod x;` declarations: (the child's module path, where its file may be).
    children: Vec<(ModPath, Vec<PathBuf>)>,
    /// `mod x { … }` blocks, by module path.
    inline: Vec<ModPath>,
    /// Items defined at module level: (module, name).
    defs: Vec<(ModPath, String)>,
    uses: Vec<Use>,
    /// Paths in code and attributes: (the module they are in, segments, line).
    paths: Vec<(ModPath, Vec<String>, usize)>,
    /// Identifiers in code (outside `use` lines), with their first line.
    idents: BTreeMap<String, usize>,
}

const DEF_KEYWORDS: [&str; 9] = [
    "fn", "struct", "enum", "trait", "type", "const", "static", "union", "mod",
];

fn ident(t: Option<&Token>) -> Option<&str> {
    match t.map(|t| &t.tok) {
        Some(Tok::Ident(s)) => Some(s),
        _ => None,
    }
}

fn punct(t: Option<&Token>, p: char) -> bool {
    t.is_some_and(|t| t.tok == Tok::Punct(p))
}

/// The index after the bracket that closes the one at `open`.
fn matching(t: &[Token], open: usize, (o, cl): (char, char)) -> usize {
    let mut depth = 0;
    let mut i = open;
    while i < t.len() {
        if t[i].tok == Tok::Punct(o) {
            depth += 1;
        } else if t[i].tok == Tok::Punct(cl) {
            depth -= 1;
            if depth == 0 {
                return i + 1;
            }
        }
        i += 1;
    }
    t.len()
}

/// The index after the item starting at `i` (to its `;` or its closing brace).
fn skip_item(t: &[Token], mut i: usize) -> usize {
    let mut nest = 0i32;
    while i < t.len() {
        match t[i].tok {
            Tok::Punct('(' | '[') => nest += 1,
            Tok::Punct(')' | ']') => nest -= 1,
            Tok::Punct(';') if nest == 0 => return i + 1,
            Tok::Punct('{') if nest == 0 => return matching(t, i, ('{', '}')),
            _ => {}
        }
        i += 1;
    }
    i
}

/// A path starting at `i`: `a::b::c` (stopping at generics and anything not an identifier).
fn path_at(t: &[Token], mut i: usize) -> (Vec<String>, usize) {
    let mut segs = Vec::new();
    while let Some(s) = ident(t.get(i)) {
        segs.push(s.to_string());
        i += 1;
        if t.get(i).map(|t| &t.tok) == Some(&Tok::PathSep) && ident(t.get(i + 1)).is_some() {
            i += 1;
        } else {
            break;
        }
    }
    (segs, i)
}

/// The bindings of a `use` tree in `t` (without `use` and `;`), below `prefix`.
fn use_tree(t: &[Token], mut i: usize, prefix: &[String], out: &mut Vec<(String, Vec<String>)>) -> usize {
    let mut path = prefix.to_vec();
    if t.get(i).map(|t| &t.tok) == Some(&Tok::PathSep) {
        path.push("::".to_string());
        i += 1;
    }
    loop {
        match t.get(i).map(|t| &t.tok) {
            Some(Tok::Ident(s)) if s != "as" => {
                path.push(s.clone());
                i += 1;
                if t.get(i).map(|t| &t.tok) == Some(&Tok::PathSep) {
                    i += 1;
                    continue;
                }
                let mut name = path.last().cloned().unwrap_or_default();
                if name == "self" {
                    path.pop();
                    name = path.last().cloned().unwrap_or_default();
                }
                if ident(t.get(i)) == Some("as") {
                    name = ident(t.get(i + 1)).unwrap_or("_").to_string();
                    i += 2;
                }
                out.push((name, path));
                return i;
            }
            Some(Tok::Punct('*')) => {
                out.push(("*".to_string(), path));
                return i + 1;
            }
            Some(Tok::Punct('{')) => {
                i += 1;
                while i < t.len() && !punct(t.get(i), '}') {
                    i = use_tree(t, i, &path, out);
                    if punct(t.get(i), ',') {
                        i += 1;
                    }
                }
                return i + 1;
            }
            _ => return i + 1,
        }
    }
}

fn is_test_cfg(attr: &[Token]) -> bool {
    let idents: Vec<&str> = attr.iter().filter_map(|t| ident(Some(t))).collect();
    idents.first() == Some(&"cfg") && idents.contains(&"test") && !idents.contains(&"not")
}

/// Read one file that is module `module`; `mod_rs` when its children live beside it (a crate
/// root, a `mod.rs`, or a file reached through `#[path]`).
fn parse(text: &str, file: &Path, module: &[String], mod_rs: bool) -> Parsed {
    let t = tokenize(text);
    let mut p = Parsed::default();
    let dir = file.parent().unwrap_or(Path::new("")).to_path_buf();
    let child_dir = if mod_rs {
        dir.clone()
    } else {
        dir.join(file.file_stem().unwrap_or_default())
    };
    let mut depth = 0usize;
    // Inline modules open here: (name, brace depth of their body).
    let mut inline: Vec<(String, usize)> = Vec::new();
    let mut test_only = false;
    let mut path_attr: Option<String> = None;
    let mut i = 0;
    while i < t.len() {
        let cur: ModPath = module
            .iter()
            .cloned()
            .chain(inline.iter().map(|(n, _)| n.clone()))
            .collect();
        let mod_depth = inline.last().map_or(0, |(_, d)| *d);
        if punct(t.get(i), '#') {
            let open = if punct(t.get(i + 1), '!') { i + 2 } else { i + 1 };
            if punct(t.get(open), '[') {
                let end = matching(&t, open, ('[', ']'));
                let attr = &t[open + 1..end.saturating_sub(1)];
                test_only |= is_test_cfg(attr);
                if ident(attr.first()) == Some("path")
                    && let Some(Token { tok: Tok::Str(s), .. }) = attr.get(2)
                {
                    path_attr = Some(s.clone());
                }
                let mut j = 0;
                while j < attr.len() {
                    let starts = ident(attr.get(j)).is_some()
                        && (j == 0 || attr[j - 1].tok != Tok::PathSep)
                        && attr.get(j + 1).map(|t| &t.tok) == Some(&Tok::PathSep);
                    if starts {
                        let (segs, next) = path_at(attr, j);
                        p.paths.push((cur.clone(), segs, attr[j].line));
                        j = next;
                    } else {
                        if let Some(s) = ident(attr.get(j)) {
                            p.idents.entry(s.to_string()).or_insert(attr[j].line);
                        }
                        j += 1;
                    }
                }
                i = end;
                continue;
            }
        }
        if test_only {
            test_only = false;
            path_attr = None;
            i = skip_item(&t, i);
            continue;
        }
        let tok = &t[i];
        match &tok.tok {
            Tok::Ident(kw) if kw == "mod" && ident(t.get(i + 1)).is_some() => {
                let name = ident(t.get(i + 1)).unwrap_or_default().to_string();
                let mut child = cur.clone();
                child.push(name.clone());
                if depth == mod_depth {
                    p.defs.push((cur.clone(), name.clone()));
                }
                if punct(t.get(i + 2), ';') {
                    let inner: PathBuf = inline.iter().map(|(n, _)| n.as_str()).collect();
                    let candidates = match path_attr.take() {
                        Some(rel) => vec![dir.join(&inner).join(rel)],
                        None => vec![
                            child_dir.join(&inner).join(format!("{name}.rs")),
                            child_dir.join(&inner).join(&name).join("mod.rs"),
                        ],
                    };
                    p.children.push((child, candidates));
                    i += 3;
                } else if punct(t.get(i + 2), '{') {
                    p.inline.push(child);
                    inline.push((name, depth + 1));
                    depth += 1;
                    i += 3;
                } else {
                    i += 2;
                }
                continue;
            }
            Tok::Ident(kw)
                if kw == "use"
                    && (ident(t.get(i + 1)).is_some()
                        || punct(t.get(i + 1), '{')
                        || t.get(i + 1).map(|t| &t.tok) == Some(&Tok::PathSep)) =>
            {
                let end = (i..t.len()).find(|&j| punct(t.get(j), ';')).unwrap_or(t.len());
                let mut bindings = Vec::new();
                let mut j = i + 1;
                while j < end {
                    j = use_tree(&t[..end], j, &[], &mut bindings);
                }
                for (name, path) in bindings {
                    p.uses.push(Use {
                        module: cur.clone(),
                        name,
                        path,
                        line: tok.line,
                    });
                }
                path_attr = None;
                i = end + 1;
                continue;
            }
            Tok::Ident(kw) if DEF_KEYWORDS.contains(&kw.as_str()) && depth == mod_depth => {
                if let Some(name) = ident(t.get(i + 1)).filter(|n| !DEF_KEYWORDS.contains(n)) {
                    p.defs.push((cur.clone(), name.to_string()));
                }
            }
            Tok::Ident(kw) if kw == "macro_rules" && punct(t.get(i + 1), '!') => {
                if let Some(name) = ident(t.get(i + 2)) {
                    p.defs.push((cur.clone(), name.to_string()));
                }
            }
            Tok::Punct('{') => depth += 1,
            Tok::Punct('}') => {
                depth = depth.saturating_sub(1);
                if inline.last().is_some_and(|(_, d)| *d > depth) {
                    inline.pop();
                }
            }
            _ => {}
        }
        if let Tok::Ident(s) = &tok.tok {
            let starts = (i == 0 || t[i - 1].tok != Tok::PathSep)
                && t.get(i + 1).map(|t| &t.tok) == Some(&Tok::PathSep);
            if starts {
                let (segs, _) = path_at(&t, i);
                p.paths.push((cur.clone(), segs, tok.line));
            }
            p.idents.entry(s.clone()).or_insert(tok.line);
        }
        i += 1;
    }
    p
}

/// Where a path leads.
#[derive(Debug, PartialEq)]
enum Res {
    Module(ModPath),
    /// An item defined in this file (by index).
    Item(usize),
    /// Outside the crate (another crate, the prelude) or not found.
    Outside,
}

/// The crate read as files and modules.
#[derive(Debug, Default)]
struct Crate {
    /// Each file: its name, its module path, what it holds.
    files: Vec<(String, ModPath, Parsed)>,
    /// Every module (file or inline) → the file holding it.
    modules: HashMap<ModPath, usize>,
    defs: HashMap<ModPath, BTreeSet<String>>,
    bindings: HashMap<ModPath, Vec<(String, Vec<String>)>>,
}

impl Crate {
    /// Read the crate whose root file is `root` (`src/lib.rs` or `src/main.rs`); file names in
    /// reports are relative to `base`.
    fn load(root: &Path, base: &Path, read: &dyn Fn(&Path) -> Option<String>) -> Crate {
        let mut krate = Crate::default();
        let mut queue = vec![(vec![root.to_path_buf()], Vec::new())];
        while let Some((candidates, module)) = queue.pop() {
            let Some((path, text)) = candidates.into_iter().find_map(|p| read(&p).map(|t| (p, t))) else {
                continue;
            };
            // A crate root, a `mod.rs` or a file named by `#[path]` keeps its children beside it.
            let mod_rs = module.is_empty()
                || path.file_name().is_some_and(|n| n == "mod.rs")
                || path.file_stem().and_then(|s| s.to_str()) != module.last().map(String::as_str);
            let parsed = parse(&text, &path, &module, mod_rs);
            let index = krate.files.len();
            krate.modules.insert(module.clone(), index);
            for m in &parsed.inline {
                krate.modules.insert(m.clone(), index);
            }
            for (m, name) in &parsed.defs {
                krate.defs.entry(m.clone()).or_default().insert(name.clone());
            }
            for u in &parsed.uses {
                krate
                    .bindings
                    .entry(u.module.clone())
                    .or_default()
                    .push((u.name.clone(), u.path.clone()));
            }
            for (child, candidates) in &parsed.children {
                queue.push((candidates.clone(), child.clone()));
            }
            let rel = path
                .strip_prefix(base)
                .unwrap_or(&path)
                .to_string_lossy()
                .replace('\\', "/");
            krate.files.push((rel, module, parsed));
        }
        krate
    }

    /// Resolve `segs` seen in module `m`; `first` while the first segment is still to be looked
    /// up in scope (where a name not found is another crate's).
    fn resolve(&self, m: &[String], segs: &[String], first: bool, budget: u32) -> Res {
        let Some((s, rest)) = segs.split_first() else {
            return Res::Module(m.to_vec());
        };
        if budget == 0 {
            return Res::Outside;
        }
        let budget = budget - 1;
        match s.as_str() {
            "crate" if first => return self.resolve(&[], rest, false, budget),
            "self" => return self.resolve(m, rest, false, budget),
            "super" => return self.resolve(&m[..m.len().saturating_sub(1)], rest, false, budget),
            "::" | "Self" => return Res::Outside,
            _ => {}
        }
        let mut child = m.to_vec();
        child.push(s.clone());
        if self.modules.contains_key(&child) {
            return self.resolve(&child, rest, false, budget);
        }
        let Some(&file) = self.modules.get(m) else {
            return Res::Outside;
        };
        if self.defs.get(m).is_some_and(|d| d.contains(s)) {
            return Res::Item(file);
        }
        let bindings = self.bindings.get(m).map(Vec::as_slice).unwrap_or_default();
        for (name, path) in bindings {
            if name == s {
                return match self.resolve(m, path, true, budget) {
                    Res::Module(mm) => self.resolve(&mm, rest, false, budget),
                    other => other,
                };
            }
        }
        for (name, path) in bindings {
            if name == "*"
                && let Res::Module(glob) = self.resolve(m, path, true, budget)
                && let found @ Res::Item(_) = self.resolve(&glob, segs, true, budget)
            {
                return found;
            }
        }
        if first { Res::Outside } else { Res::Item(file) }
    }

    /// Every file-to-file edge with its first evidence: `(from, to) → (line, what)`.
    fn edges(&self) -> BTreeMap<(usize, usize), (usize, String)> {
        let mut edges = BTreeMap::new();
        let budget = 32;
        for (f, (_, module, p)) in self.files.iter().enumerate() {
            let mut add = |to: Res, line: usize, what: String| {
                // A module's own file is part of it: a child may use what an ancestor defines.
                if let Res::Item(t) = to
                    && t != f
                    && !module.starts_with(&self.files[t].1)
                {
                    edges.entry((f, t)).or_insert((line, what));
                }
            };
            for u in &p.uses {
                let what = u.path.join("::");
                if u.name == "*" {
                    match self.resolve(&u.module, &u.path, true, budget) {
                        Res::Module(glob) => {
                            for name in p.idents.keys() {
                                let to = self.resolve(&glob, std::slice::from_ref(name), true, budget);
                                add(to, u.line, format!("{what}::* ({name})"));
                            }
                        }
                        other => add(other, u.line, format!("{what}::*")),
                    }
                } else if u.name == "_" || p.idents.contains_key(&u.name) {
                    add(self.resolve(&u.module, &u.path, true, budget), u.line, what);
                }
            }
            for (m, segs, line) in &p.paths {
                add(self.resolve(m, segs, true, budget), *line, segs.join("::"));
            }
        }
        edges
    }

    /// Each circle among files, written `a.rs → b.rs → a.rs` with the line naming each step.
    fn circles(&self) -> Vec<String> {
        let edges = self.edges();
        let n = self.files.len();
        let mut next: Vec<Vec<usize>> = vec![Vec::new(); n];
        for &(a, b) in edges.keys() {
            next[a].push(b);
        }
        let mut report = Vec::new();
        for component in strongly_connected(&next) {
            if component.len() < 2 {
                continue;
            }
            let inside: BTreeSet<usize> = component.iter().copied().collect();
            let start = *component
                .iter()
                .min_by_key(|&&f| &self.files[f].0)
                .unwrap_or(&component[0]);
            // The shortest way from `start` back to itself inside the component.
            let mut from: HashMap<usize, usize> = HashMap::new();
            let mut queue = std::collections::VecDeque::from([start]);
            'search: while let Some(a) = queue.pop_front() {
                for &b in &next[a] {
                    if !inside.contains(&b) {
                        continue;
                    }
                    if b == start {
                        from.insert(start, a);
                        break 'search;
                    }
                    if let std::collections::hash_map::Entry::Vacant(e) = from.entry(b) {
                        e.insert(a);
                        queue.push_back(b);
                    }
                }
            }
            let mut cycle = vec![start];
            let mut at = from[&start];
            while at != start {
                cycle.push(at);
                at = from[&at];
            }
            cycle.push(start);
            cycle.reverse();
            let names: Vec<&str> = cycle.iter().map(|&f| self.files[f].0.as_str()).collect();
            let mut text = names.join(" → ");
            for pair in cycle.windows(2) {
                let (line, what) = &edges[&(pair[0], pair[1])];
                text.push_str(&format!("\n    {}:{line} names `{what}`", self.files[pair[0]].0));
            }
            if component.len() > cycle.len() - 1 {
                let mut all: Vec<&str> = component.iter().map(|&f| self.files[f].0.as_str()).collect();
                all.sort_unstable();
                text.push_str(&format!(
                    "\n    (one circle of {} files: {})",
                    all.len(),
                    all.join(", ")
                ));
            }
            report.push(text);
        }
        report.sort();
        report
    }
}

/// Tarjan's strongly connected components.
fn strongly_connected(next: &[Vec<usize>]) -> Vec<Vec<usize>> {
    struct State<'a> {
        next: &'a [Vec<usize>],
        index: Vec<Option<usize>>,
        low: Vec<usize>,
        on_stack: Vec<bool>,
        stack: Vec<usize>,
        counter: usize,
        out: Vec<Vec<usize>>,
    }
    fn visit(s: &mut State<'_>, v: usize) {
        s.index[v] = Some(s.counter);
        s.low[v] = s.counter;
        s.counter += 1;
        s.stack.push(v);
        s.on_stack[v] = true;
        for &w in s.next[v].clone().iter() {
            match s.index[w] {
                None => {
                    visit(s, w);
                    s.low[v] = s.low[v].min(s.low[w]);
                }
                Some(iw) if s.on_stack[w] => s.low[v] = s.low[v].min(iw),
                Some(_) => {}
            }
        }
        if Some(s.low[v]) == s.index[v] {
            let mut component = Vec::new();
            while let Some(w) = s.stack.pop() {
                s.on_stack[w] = false;
                component.push(w);
                if w == v {
                    break;
                }
            }
            s.out.push(component);
        }
    }
    let n = next.len();
    let mut s = State {
        next,
        index: vec![None; n],
        low: vec![0; n],
        on_stack: vec![false; n],
        stack: Vec::new(),
        counter: 0,
        out: Vec::new(),
    };
    for v in 0..n {
        if s.index[v].is_none() {
            visit(&mut s, v);
        }
    }
    s.out
}

fn crate_circles(manifest_dir: &Path) -> (usize, Vec<String>) {
    let src = manifest_dir.join("src");
    let root = ["lib.rs", "main.rs"]
        .iter()
        .map(|f| src.join(f))
        .find(|p| p.exists())
        .expect("a crate root: src/lib.rs or src/main.rs");
    let krate = Crate::load(&root, manifest_dir, &|p| std::fs::read_to_string(p).ok());
    (krate.files.len(), krate.circles())
}

/// The workspace's members, read from its `Cargo.toml` (this file is the cli package's test, one
/// folder down).
fn members() -> (PathBuf, Vec<String>) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let manifest = std::fs::read_to_string(root.join("Cargo.toml")).expect("the workspace's Cargo.toml");
    let doc: toml::Table = manifest.parse().expect("the workspace's Cargo.toml parses");
    let members = doc["workspace"]["members"]
        .as_array()
        .expect("[workspace] members");
    let members = members
        .iter()
        .map(|m| m.as_str().expect("a member path").to_string())
        .collect();
    (root, members)
}

#[test]
fn no_two_files_of_any_crate_import_each_other() {
    let (root, members) = members();
    assert!(members.len() >= 10, "the workspace lists only {members:?}");
    let mut found = Vec::new();
    for m in &members {
        let dir = root.join(m);
        let (files, circles) = crate_circles(&dir);
        assert!(files > 1, "read only {files} files under {}", dir.display());
        found.extend(circles.into_iter().map(|c| format!("{m}: {c}")));
    }
    assert!(
        found.is_empty(),
        "files importing each other in a circle (put what they share in a third file; \
         rule in tests/import_circles.rs):\n{}",
        found.join("\n")
    );
}

#[test]
fn the_check_finds_a_circle_and_lets_a_parent_re_export_its_children() {
    let files: HashMap<PathBuf, &str> = HashMap::from([
        (
            PathBuf::from("src/lib.rs"),
            "mod a;\nmod b;\nmod svc;\n#[cfg(test)]\nmod tests;\n",
        ),
        (
            PathBuf::from("src/a.rs"),
            "use crate::b::B;\npub(crate) struct A(B);\n",
        ),
        (
            PathBuf::from("src/b.rs"),
            "/// crate::svc::Never in a comment\npub(crate) struct B;\nfn f() { let _ = \"crate::svc::X\"; super::a::A(B); }\n",
        ),
        (
            PathBuf::from("src/svc.rs"),
            "mod jobs;\nmod state;\npub(crate) use state::State;\npub(crate) use jobs::*;\n\
             pub(crate) struct Shared;\nfn start() { jobs::run(Shared) }\n",
        ),
        (PathBuf::from("src/svc/state.rs"), "pub(crate) struct State;\n"),
        (
            PathBuf::from("src/svc/jobs.rs"),
            "use crate::svc::State;\nimpl State { fn go(&self) {} }\n\
             pub(crate) fn run(_: super::Shared) {}\n",
        ),
        (PathBuf::from("src/tests.rs"), "use crate::svc::run;\n"),
    ]);
    let krate = Crate::load(Path::new("src/lib.rs"), Path::new(""), &|p| {
        files.get(p).map(|s| s.to_string())
    });
    assert_eq!(krate.files.len(), 6, "tests.rs is cfg(test)");
    let name = |f: usize| krate.files[f].0.as_str();
    let edges: Vec<(&str, &str)> = krate.edges().keys().map(|&(a, b)| (name(a), name(b))).collect();
    assert!(edges.contains(&("src/svc.rs", "src/svc/jobs.rs")), "{edges:?}");
    assert!(
        edges.contains(&("src/svc/jobs.rs", "src/svc/state.rs")),
        "through the re-export: {edges:?}"
    );
    assert!(
        !edges
            .iter()
            .any(|e| e.0 == "src/svc/jobs.rs" && e.1 == "src/svc.rs"),
        "a child may use what its parent defines: {edges:?}"
    );
    let circles = krate.circles();
    assert_eq!(circles.len(), 1, "{circles:?}");
    assert!(
        circles[0].starts_with("src/a.rs → src/b.rs → src/a.rs"),
        "{}",
        circles[0]
    );
    assert!(
        circles[0].contains("src/b.rs:3 names `super::a::A`"),
        "{}",
        circles[0]
    );
}
