//! The shape of the code, checked on its sources (prints what it finds):
//!
//! - no circle between the top-level modules of a crate, nor between the
//!   files of one module (a module's `mod.rs` re-exports its parts and is
//!   left out: its own items are what its parts share);
//! - the layers of the `tumble` crate: the model types import no pipeline,
//!   `io` imports only the model, the simulator imports no pipeline;
//! - no function longer than [`MAX_FUNCTION_LINES`] and no file longer than
//!   [`MAX_FILE_LINES`], tests and examples included.
//!
//! Dependencies are read off the paths in the code (`crate::a::b`, `super::b`,
//! a parent's re-exports resolved to the file that defines them), with
//! comments, strings and `#[cfg(test)]` modules left out.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The longest function (signature to closing brace) \[lines\].
const MAX_FUNCTION_LINES: usize = 120;
/// The longest source file \[lines\].
const MAX_FILE_LINES: usize = 800;

/// The crates' source roots, relative to the workspace.
const CRATES: [&str; 3] = ["src", "solvers/src", "factors/src"];

/// Top-level modules of `tumble` that sit below the pipelines, with the
/// modules each may import (besides the crate's other libraries).
const LAYERS: [(&str, &[&str]); 5] = [
    ("error", &[]),
    ("plot", &["error"]),
    ("model", &["error", "plot"]),
    ("io", &["error", "plot", "model"]),
    ("sim", &["error", "plot", "model", "io"]),
];

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    let mut entries: Vec<_> = entries.flatten().map(|e| e.path()).collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            if p.file_name().is_some_and(|n| n != "target") {
                rust_files(&p, out);
            }
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

/// The source with comments, string and character literals blanked (line
/// breaks kept, so line numbers stay).
fn strip(src: &str) -> String {
    let b = src.as_bytes();
    let mut out = String::with_capacity(src.len());
    let mut i = 0;
    let keep_lines = |s: &[u8], out: &mut String| {
        out.extend(s.iter().filter(|&&c| c == b'\n').map(|_| '\n'));
    };
    while i < b.len() {
        let rest = &b[i..];
        if rest.starts_with(b"//") {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
        } else if rest.starts_with(b"/*") {
            let end = find(b, i + 2, b"*/").map_or(b.len(), |j| j + 2);
            keep_lines(&b[i..end], &mut out);
            i = end;
        } else if let Some(hashes) = raw_string_start(b, i) {
            let body = i + 2 + hashes;
            let close: Vec<u8> = std::iter::once(b'"').chain(std::iter::repeat_n(b'#', hashes)).collect();
            let end = find(b, body, &close).map_or(b.len(), |j| j + close.len());
            out.push_str("\"\"");
            keep_lines(&b[i..end], &mut out);
            i = end;
        } else if b[i] == b'"' {
            let mut j = i + 1;
            while j < b.len() && b[j] != b'"' {
                j += if b[j] == b'\\' { 2 } else { 1 };
            }
            out.push_str("\"\"");
            keep_lines(&b[i..j.min(b.len())], &mut out);
            i = j + 1;
        } else if let Some(len) = char_literal(b, i) {
            out.push_str("' '");
            i += len;
        } else {
            let ch = src[i..].chars().next().expect("in bounds");
            out.push(ch);
            i += ch.len_utf8();
        }
    }
    out
}

fn find(b: &[u8], from: usize, pat: &[u8]) -> Option<usize> {
    (from..b.len().saturating_sub(pat.len() - 1)).find(|&j| b[j..].starts_with(pat))
}

/// `r"`, `r#"`, `br"`… starting at `i` (not inside an identifier): the number of `#`.
fn raw_string_start(b: &[u8], i: usize) -> Option<usize> {
    if i > 0 && (b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_') {
        return None;
    }
    let j = if b[i] == b'b' { i + 1 } else { i };
    if b.get(j) != Some(&b'r') {
        return None;
    }
    let hashes = b[j + 1..].iter().take_while(|&&c| c == b'#').count();
    (b.get(j + 1 + hashes) == Some(&b'"')).then_some(hashes + (j - i))
}

/// A character literal at `i` (`'a'`, `'\n'`, `'\u{1F}'`, `'é'`): its length; None for a lifetime.
fn char_literal(b: &[u8], i: usize) -> Option<usize> {
    if b[i] != b'\'' {
        return None;
    }
    if b.get(i + 1) == Some(&b'\\') {
        let close = (i + 3..(i + 12).min(b.len())).find(|&j| b[j] == b'\'')?;
        return Some(close - i + 1);
    }
    let ch_len = std::str::from_utf8(&b[i + 1..(i + 5).min(b.len())])
        .ok()
        .or_else(|| std::str::from_utf8(&b[i + 1..(i + 2).min(b.len())]).ok())
        .and_then(|s| s.chars().next())
        .map(char::len_utf8)
        .unwrap_or(1);
    (b.get(i + 1 + ch_len) == Some(&b'\'')).then_some(ch_len + 2)
}

/// The code without its `#[cfg(test)]` items (tests may use anything).
fn without_tests(code: &str) -> String {
    let mut out = String::new();
    let mut rest = code;
    while let Some(k) = rest.find("#[cfg(test)]") {
        out.push_str(&rest[..k]);
        let after = &rest[k..];
        let open = after.find('{');
        let semi = after.find(';');
        let end = match (open, semi) {
            (Some(o), Some(s)) if s < o => s + 1,
            (Some(o), _) => matching_brace(after, o).map_or(after.len(), |c| c + 1),
            _ => after.len(),
        };
        out.extend(after[..end].chars().filter(|&c| c == '\n'));
        rest = &after[end..];
    }
    out.push_str(rest);
    out
}

fn matching_brace(s: &str, open: usize) -> Option<usize> {
    let mut depth = 0usize;
    for (j, c) in s[open..].char_indices() {
        match c {
            '{' => depth += 1,
            '}' => {
                depth -= 1;
                if depth == 0 {
                    return Some(open + j);
                }
            }
            _ => {}
        }
    }
    None
}

/// A file's module path within its crate (`src/vio/input.rs` → `[vio, input]`).
fn module_path(root: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(root).expect("under its root").with_extension("");
    let mut parts: Vec<String> = rel.components().map(|c| c.as_os_str().to_string_lossy().into_owned()).collect();
    if matches!(parts.last().map(String::as_str), Some("mod" | "lib" | "main")) {
        parts.pop();
    }
    parts
}

fn is_ident(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

/// Every path the code names, split into segments (`crate::a::{b, c::d}`
/// gives `[crate, a, b]` and `[crate, a, c, d]`); `$crate` (a macro's, which
/// expands in its caller) is left out.
fn paths(code: &str) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    let chars: Vec<char> = code.chars().collect();
    let mut i = 0;
    while i < chars.len() {
        let at_word = i == 0 || !(is_ident(chars[i - 1]) || chars[i - 1] == '$' || chars[i - 1] == ':');
        if at_word && is_ident(chars[i]) {
            let (segs, next) = path_at(&chars, i, Vec::new());
            out.extend(segs.into_iter().filter(|s| s.len() > 1));
            i = next.max(i + 1);
        } else {
            i += 1;
        }
    }
    out
}

/// The paths starting at `i` (a `{…}` group fans out), prefixed by `prefix`.
fn path_at(chars: &[char], mut i: usize, prefix: Vec<String>) -> (Vec<Vec<String>>, usize) {
    let mut segs = prefix;
    loop {
        let start = i;
        while i < chars.len() && is_ident(chars[i]) {
            i += 1;
        }
        if i == start {
            break;
        }
        segs.push(chars[start..i].iter().collect());
        let mut j = i;
        while j < chars.len() && chars[j].is_whitespace() {
            j += 1;
        }
        if chars.get(j) == Some(&':') && chars.get(j + 1) == Some(&':') {
            i = j + 2;
            while i < chars.len() && chars[i].is_whitespace() {
                i += 1;
            }
            if chars.get(i) == Some(&'{') {
                return group_at(chars, i + 1, segs);
            }
        } else {
            break;
        }
    }
    (vec![segs], i)
}

fn group_at(chars: &[char], mut i: usize, prefix: Vec<String>) -> (Vec<Vec<String>>, usize) {
    let mut out = Vec::new();
    loop {
        while i < chars.len() && (chars[i].is_whitespace() || chars[i] == ',') {
            i += 1;
        }
        match chars.get(i) {
            None => return (out, i),
            Some('}') => return (out, i + 1),
            Some(c) if is_ident(*c) => {
                let (segs, next) = path_at(chars, i, prefix.clone());
                out.extend(segs);
                // skip `as name` and anything up to the next separator
                i = next;
                while i < chars.len() && chars[i] != ',' && chars[i] != '}' {
                    i += 1;
                }
            }
            Some(_) => i += 1,
        }
    }
}

/// One crate's files: module path → code (tests removed).
struct CrateSources {
    files: BTreeMap<Vec<String>, String>,
}

impl CrateSources {
    fn read(root: &Path) -> CrateSources {
        let mut list = Vec::new();
        rust_files(root, &mut list);
        let files = list
            .iter()
            .filter(|f| f.file_name().is_some_and(|n| n != "main.rs"))
            .map(|f| {
                let src = std::fs::read_to_string(f).expect("readable source");
                (module_path(root, f), without_tests(&strip(&src)))
            })
            .collect();
        CrateSources { files }
    }

    /// Where the name `name`, seen from module `module`, is defined: a child
    /// module file, or what `module` re-exports (`pub use child::…`,
    /// `pub use crate::other::…`), followed `depth` re-exports deep.
    fn resolve(&self, module: &[String], name: &str, depth: usize) -> Vec<String> {
        let mut child = module.to_vec();
        child.push(name.to_string());
        if self.files.contains_key(&child) {
            return child;
        }
        let Some(code) = self.files.get(module).filter(|_| depth < 4) else { return module.to_vec() };
        for path in paths(code) {
            if path.last().is_none_or(|l| l != name) {
                continue;
            }
            let mut target = module.to_vec();
            target.push(path[0].clone());
            if self.files.contains_key(&target) {
                return self.walk(target, &path[1..], depth + 1);
            }
            if let Some(t) = self.target(module, &path, depth + 1) {
                if t != module {
                    return t;
                }
            }
        }
        module.to_vec()
    }

    /// The module file a path in `module`'s code points to (crate-absolute);
    /// None for a path into another crate or a type's items.
    fn target(&self, module: &[String], path: &[String], depth: usize) -> Option<Vec<String>> {
        let mut base = module.to_vec();
        let rest = match path[0].as_str() {
            "crate" => {
                base.clear();
                &path[1..]
            }
            "self" => &path[1..],
            "super" => {
                let supers = path.iter().take_while(|s| *s == "super").count();
                base.truncate(base.len().saturating_sub(supers));
                &path[supers..]
            }
            _ => return None,
        };
        Some(self.walk(base, rest, depth))
    }

    /// From module `base`, down the segments that name module files, then
    /// through a re-export of the first that does not.
    fn walk(&self, mut base: Vec<String>, rest: &[String], depth: usize) -> Vec<String> {
        for seg in rest {
            let mut next = base.clone();
            next.push(seg.clone());
            if !self.files.contains_key(&next) {
                return self.resolve(&base, seg, depth);
            }
            base = next;
        }
        base
    }

    /// Edges between module files (crate-absolute module paths).
    fn edges(&self) -> BTreeSet<(Vec<String>, Vec<String>)> {
        let mut out = BTreeSet::new();
        for (module, code) in &self.files {
            for path in paths(code) {
                if let Some(t) = self.target(module, &path, 0) {
                    if &t != module {
                        out.insert((module.clone(), t));
                    }
                }
            }
        }
        out
    }
}

/// The strongly connected components with more than one node (Tarjan).
fn circles(graph: &BTreeMap<String, BTreeSet<String>>) -> Vec<Vec<String>> {
    struct State<'a> {
        graph: &'a BTreeMap<String, BTreeSet<String>>,
        index: BTreeMap<&'a str, usize>,
        low: BTreeMap<&'a str, usize>,
        stack: Vec<&'a str>,
        on_stack: BTreeSet<&'a str>,
        out: Vec<Vec<String>>,
    }
    fn visit<'a>(s: &mut State<'a>, v: &'a str) {
        let n = s.index.len();
        s.index.insert(v, n);
        s.low.insert(v, n);
        s.stack.push(v);
        s.on_stack.insert(v);
        if let Some(ws) = s.graph.get(v) {
            for w in ws {
                if !s.index.contains_key(w.as_str()) {
                    visit(s, w);
                    let lw = s.low[w.as_str()];
                    let lv = s.low.get_mut(v).expect("visited");
                    *lv = (*lv).min(lw);
                } else if s.on_stack.contains(w.as_str()) {
                    let iw = s.index[w.as_str()];
                    let lv = s.low.get_mut(v).expect("visited");
                    *lv = (*lv).min(iw);
                }
            }
        }
        if s.low[v] == s.index[v] {
            let mut comp = Vec::new();
            while let Some(w) = s.stack.pop() {
                s.on_stack.remove(w);
                comp.push(w.to_string());
                if w == v {
                    break;
                }
            }
            if comp.len() > 1 {
                comp.sort();
                s.out.push(comp);
            }
        }
    }
    let mut s = State {
        graph,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on_stack: BTreeSet::new(),
        out: Vec::new(),
    };
    for v in graph.keys() {
        if !s.index.contains_key(v.as_str()) {
            visit(&mut s, v);
        }
    }
    s.out
}

/// Per crate: the top-level module graph, and each module's graph of its files.
fn module_graphs(root: &Path) -> BTreeMap<String, BTreeMap<String, BTreeSet<String>>> {
    let sources = CrateSources::read(root);
    let mut graphs: BTreeMap<String, BTreeMap<String, BTreeSet<String>>> = BTreeMap::new();
    for (from, to) in sources.edges() {
        let (Some(a), Some(b)) = (from.first(), to.first()) else { continue };
        if a != b {
            graphs.entry(String::new()).or_default().entry(a.clone()).or_default().insert(b.clone());
            continue;
        }
        // Inside one module: between its direct parts, the module's own file left out.
        let depth = common_prefix(&from, &to);
        if depth < from.len() && depth < to.len() {
            let scope = from[..depth].join("::");
            graphs.entry(scope).or_default().entry(from[depth].clone()).or_default().insert(to[depth].clone());
        }
    }
    graphs
}

fn common_prefix(a: &[String], b: &[String]) -> usize {
    a.iter().zip(b).take_while(|(x, y)| x == y).count()
}

#[test]
fn no_circle_between_modules() {
    let mut found = Vec::new();
    for krate in CRATES {
        let graphs = module_graphs(&workspace().join(krate));
        if let Some(top) = graphs.get("") {
            println!("{krate}: top-level modules and what they import");
            for (m, deps) in top {
                println!("  {m:<12} → {}", deps.iter().cloned().collect::<Vec<_>>().join(", "));
            }
        }
        for (scope, graph) in &graphs {
            for circle in circles(graph) {
                let name = if scope.is_empty() { krate.to_string() } else { format!("{krate}: {scope}") };
                found.push(format!("{name}: {}", circle.join(" ⇄ ")));
            }
        }
    }
    assert!(found.is_empty(), "modules that import one another:\n  {}", found.join("\n  "));
}

#[test]
fn the_layers_below_the_pipelines_import_downward_only() {
    let graphs = module_graphs(&workspace().join("src"));
    let top = graphs.get("").cloned().unwrap_or_default();
    let mut wrong = Vec::new();
    for (module, allowed) in LAYERS {
        for dep in top.get(module).into_iter().flatten() {
            if !allowed.contains(&dep.as_str()) {
                wrong.push(format!("{module} imports {dep} (may import: {})", allowed.join(", ")));
            }
        }
    }
    assert!(wrong.is_empty(), "layers imported upward:\n  {}", wrong.join("\n  "));
}

/// Every `fn` with a body: (name, first line, length in lines).
fn functions(code: &str) -> Vec<(String, usize, usize)> {
    let mut out = Vec::new();
    let mut search = 0;
    while let Some(k) = code[search..].find("fn ") {
        let at = search + k;
        search = at + 3;
        if at > 0 && code[..at].chars().next_back().is_some_and(is_ident) {
            continue;
        }
        let name: String = code[at + 3..].trim_start().chars().take_while(|&c| is_ident(c)).collect();
        if name.is_empty() {
            continue;
        }
        let Some(rel) = code[at..].find(['{', ';']) else { continue };
        if code[at + rel..].starts_with(';') {
            continue;
        }
        let Some(close) = matching_brace(code, at + rel) else { continue };
        let first = code[..at].matches('\n').count() + 1;
        let last = code[..close].matches('\n').count() + 1;
        out.push((name, first, last - first + 1));
    }
    out
}

#[test]
fn functions_and_files_stay_short() {
    let mut files = Vec::new();
    for dir in ["src", "solvers", "factors", "tests", "examples", "bench", "fuzz", "python"] {
        rust_files(&workspace().join(dir), &mut files);
    }
    let mut long = Vec::new();
    for f in &files {
        let src = std::fs::read_to_string(f).expect("readable source");
        let rel = f.strip_prefix(workspace()).unwrap_or(f).display().to_string();
        let lines = src.lines().count();
        if lines > MAX_FILE_LINES {
            long.push(format!("{rel}: {lines} lines (at most {MAX_FILE_LINES})"));
        }
        for (name, line, len) in functions(&strip(&src)) {
            if len > MAX_FUNCTION_LINES {
                long.push(format!("{rel}:{line}: fn {name} has {len} lines (at most {MAX_FUNCTION_LINES})"));
            }
        }
    }
    println!("{} files read", files.len());
    assert!(long.is_empty(), "too long:\n  {}", long.join("\n  "));
}

#[test]
fn the_checks_see_what_they_check() {
    let code = strip("use crate::a::{b, c::d as e};\nfn f() { let s = \"crate::x::y {\"; super::g::h(); }\n");
    let p = paths(&code);
    assert!(p.contains(&vec!["crate".into(), "a".into(), "b".into()]));
    assert!(p.contains(&vec!["crate".into(), "a".into(), "c".into(), "d".into()]));
    assert!(p.contains(&vec!["super".into(), "g".into(), "h".into()]));
    assert!(!p.iter().any(|s| s.contains(&"x".to_string())), "strings are blanked: {p:?}");
    let fns = functions(&code);
    assert_eq!(fns, vec![("f".to_string(), 2, 1)]);
    let lifetimes = strip("fn g<'a>(x: &'a str) -> char { 'x' }");
    assert_eq!(functions(&lifetimes).len(), 1);
    let mut g = BTreeMap::new();
    g.insert("a".to_string(), BTreeSet::from(["b".to_string()]));
    g.insert("b".to_string(), BTreeSet::from(["a".to_string()]));
    g.insert("c".to_string(), BTreeSet::from(["a".to_string()]));
    assert_eq!(circles(&g), vec![vec!["a".to_string(), "b".to_string()]]);
}
