//! The file-level import graph of a crate's sources, for the layer tests of core and the coordinator
//! (`core/tests/module_layers.rs`, `coordinator/tests/module_layers.rs`); `tools/structure.py` draws the same
//! graph.
//!
//! A file names another when a path in its code resolves there: `use crate::a::b…`, `crate::a::b::…`,
//! `use super::x`, `super::x::…`, `self::x::…`, `child::x` for a module the file declares, and names brought in
//! by `use`. `super` and `self` are relative to the module the path sits in (a file's, or an inline `mod` inside
//! it). A path goes to the file of its longest prefix that is a module file (`a/b.rs` or `a/b/mod.rs`, then
//! `a.rs` or `a/mod.rs`), and on to the file a name comes from when that file brings the name in with a `use`
//! (`pub use child::X`, `pub use types::*`) rather than defining it. Comments, the insides of string literals,
//! `pub(in …)`, `#[cfg(test)]` items and the files of `#[cfg(test)] mod x;` are not read, and a `mod child;`
//! declaration is no edge: a folder's `mod.rs` names its child only where its code uses the child's items.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// A module path inside the crate: `a::b` is `["a", "b"]`, the crate root `[]`.
type Module = Vec<String>;

/// For each file (its path under `src`), the files its code names, each with the lines and paths that name it.
pub type Graph = BTreeMap<String, BTreeMap<String, Vec<(usize, String)>>>;

/// The import cycles between the files of the crate whose sources are in `src`, each as
/// `a.rs -> b.rs -> a.rs` followed by one line per edge saying where the first file names the second.
pub fn crate_cycles(src: &Path) -> Vec<String> {
    let graph = graph(&read_crate(src));
    cycles(&graph).iter().map(|c| describe(&graph, c)).collect()
}

/// (path under `src`, text) of every `.rs` file of the crate's library (or of its binary, when it has no library:
/// a binary beside a library is a crate of its own that reaches the library by its name).
pub fn read_crate(src: &Path) -> Vec<(String, String)> {
    let mut rels = Vec::new();
    let mut stack = vec![src.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for e in std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
            let p = e.unwrap_or_else(|e| panic!("{}: {e}", dir.display())).path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "rs") {
                let rel = p.strip_prefix(src).unwrap_or(&p);
                rels.push(rel.components().map(|c| c.as_os_str().to_string_lossy()).collect::<Vec<_>>().join("/"));
            }
        }
    }
    let has_lib = rels.iter().any(|r| r == "lib.rs");
    rels.retain(|r| !(has_lib && (r == "main.rs" || r.starts_with("bin/"))));
    rels.sort();
    rels.into_iter()
        .map(|r| {
            let text = std::fs::read_to_string(src.join(&r)).unwrap_or_else(|e| panic!("{r}: {e}"));
            (r, text)
        })
        .collect()
}

/// The graph of the files `sources` (path under `src`, text), less the files of test modules.
pub fn graph(sources: &[(String, String)]) -> Graph {
    let mut code = BTreeMap::new();
    let mut tests = Vec::new();
    for (rel, text) in sources {
        let m = module_of(rel);
        let (c, test_mods) = strip_tests(lex(text));
        tests.extend(test_mods.into_iter().map(|t| [m.clone(), vec![t]].concat()));
        code.insert(m, (rel.clone(), c));
    }
    code.retain(|m, _| !tests.iter().any(|t| m.starts_with(t)));
    let mods: BTreeSet<Module> = code.keys().cloned().collect();
    let scans: BTreeMap<Module, Scan> = code.iter().map(|(m, (_, c))| (m.clone(), Scan::new(m, c, &mods))).collect();
    let mut edges = Graph::new();
    for (m, (rel, _)) in &code {
        let out = edges.entry(rel.clone()).or_default();
        let scan = &scans[m];
        for (offset, written, target) in &scan.refs {
            let Some(dst) = locate(&mods, &scans, target, &mut BTreeSet::new()) else { continue };
            if dst != *m {
                out.entry(code[&dst].0.clone()).or_default().push((line_of(&scan.code, *offset), written.clone()));
            }
        }
    }
    edges
}

/// Every elementary cycle of the graph (up to 200), each as its files, the first repeated last.
pub fn cycles(graph: &Graph) -> Vec<Vec<String>> {
    let mut walk =
        Walk { graph, order: graph.keys().enumerate().map(|(k, f)| (f.as_str(), k)).collect(), found: vec![] };
    for start in graph.keys() {
        walk.search(start, &mut vec![start.clone()]);
    }
    walk.found
}

/// `a.rs -> b.rs -> a.rs`, then for each edge the first line of the first file that names the second.
fn describe(graph: &Graph, cycle: &[String]) -> String {
    let mut out = cycle.join(" -> ");
    for pair in cycle.windows(2) {
        if let Some((line, written)) = graph[&pair[0]].get(&pair[1]).and_then(|refs| refs.first()) {
            out.push_str(&format!("\n    {}:{line} names {written} ({})", pair[0], pair[1]));
        }
    }
    out
}

/// The depth-first search of [`cycles`]: from each file, the cycles through files after it in `order`.
struct Walk<'a> {
    graph: &'a Graph,
    order: BTreeMap<&'a str, usize>,
    found: Vec<Vec<String>>,
}

impl Walk<'_> {
    fn search(&mut self, start: &str, path: &mut Vec<String>) {
        let graph = self.graph;
        let last = path.last().cloned().unwrap_or_default();
        for next in graph.get(&last).into_iter().flat_map(BTreeMap::keys) {
            if self.found.len() >= 200 {
                return;
            }
            if next == start {
                self.found.push([path.as_slice(), &[start.to_string()]].concat());
            } else if self.order.get(next.as_str()) > self.order.get(start) && !path.contains(next) {
                path.push(next.clone());
                self.search(start, path);
                path.pop();
            }
        }
    }
}

/// The module path of a file from its path under `src`: `a/b.rs` and `a/b/mod.rs` are `a::b`.
fn module_of(rel: &str) -> Module {
    let mut parts: Module = rel.trim_end_matches(".rs").split('/').map(str::to_string).collect();
    if parts.last().is_some_and(|p| p == "mod") || parts == ["lib"] || parts == ["main"] {
        parts.pop();
    }
    parts
}

// ------------------------------------------------------------------------------------------------- lexing

fn is_ident(c: u8) -> bool {
    c.is_ascii_alphanumeric() || c == b'_'
}

/// `text` with comments blanked (spaces), the insides of string and char literals replaced by `s` and the names of
/// lifetimes by `l`; newlines are kept, so offsets and line numbers stay those of the file.
fn lex(text: &str) -> Vec<u8> {
    let t: Vec<char> = text.chars().collect();
    let n = t.len();
    let starts = |i: usize, p: &str| p.chars().enumerate().all(|(k, c)| t.get(i + k) == Some(&c));
    let after_ident = |i: usize| i > 0 && (t[i - 1].is_alphanumeric() || t[i - 1] == '_');
    let blank =
        |out: &mut String, s: &[char], fill: char| out.extend(s.iter().map(|&c| if c == '\n' { c } else { fill }));
    let mut out = String::with_capacity(text.len());
    let mut i = 0;
    while i < n {
        if starts(i, "//") {
            let j = (i..n).find(|&j| t[j] == '\n').unwrap_or(n);
            blank(&mut out, &t[i..j], ' ');
            i = j;
        } else if starts(i, "/*") {
            let (mut depth, mut j) = (1, i + 2);
            while j < n && depth > 0 {
                if starts(j, "/*") {
                    (depth, j) = (depth + 1, j + 2);
                } else if starts(j, "*/") {
                    (depth, j) = (depth - 1, j + 2);
                } else {
                    j += 1;
                }
            }
            blank(&mut out, &t[i..j.min(n)], ' ');
            i = j;
        } else if let Some((open, hashes)) = raw_string(&t, i).filter(|_| !after_ident(i)) {
            let close = format!("\"{}", "#".repeat(hashes));
            let j = (open..n).find(|&j| starts(j, &close)).unwrap_or(n);
            out.extend(&t[i..open]);
            blank(&mut out, &t[open..j], 's');
            out.push_str(&close);
            i = j + close.len();
        } else if t[i] == '"' || (starts(i, "b\"") && !after_ident(i)) {
            let open = if t[i] == 'b' { i + 2 } else { i + 1 };
            let mut j = open;
            while j < n && t[j] != '"' {
                j += if t[j] == '\\' { 2 } else { 1 };
            }
            out.extend(&t[i..open]);
            blank(&mut out, &t[open..j.min(n)], 's');
            out.push('"');
            i = j + 1;
        } else if t[i] == '\'' {
            if let Some(end) = char_literal(&t, i) {
                out.push('\'');
                out.extend(std::iter::repeat_n('s', end - i - 2));
                out.push('\'');
                i = end;
            } else {
                // A lifetime or a label: its name is no item's (`&'static T` defines no `T`).
                let end = (i + 1..n).find(|&k| !(t[k].is_alphanumeric() || t[k] == '_')).unwrap_or(n);
                out.push('\'');
                out.extend(std::iter::repeat_n('l', end - i - 1));
                i = end;
            }
        } else {
            out.push(t[i]);
            i += 1;
        }
    }
    out.into_bytes()
}

/// At `b?r#*"`: the offset of the raw string's first character and its number of `#`.
fn raw_string(t: &[char], i: usize) -> Option<(usize, usize)> {
    let mut k = if t.get(i) == Some(&'b') { i + 1 } else { i };
    if t.get(k) != Some(&'r') {
        return None;
    }
    k += 1;
    let hashes = t[k..].iter().take_while(|&&c| c == '#').count();
    (t.get(k + hashes) == Some(&'"')).then_some((k + hashes + 1, hashes))
}

/// At a `'` that opens a char literal (`'a'`, `'\n'`, `'\x41'`, `'\u{1F600}'`): the offset just after it.
fn char_literal(t: &[char], i: usize) -> Option<usize> {
    let at = |k: usize| t.get(k).copied();
    let hex = |k: usize| at(k).is_some_and(|c| c.is_ascii_hexdigit());
    if at(i + 1) == Some('\\') {
        let mut ends = Vec::new();
        if at(i + 2) == Some('x') && hex(i + 3) && hex(i + 4) {
            ends.push(i + 5);
        }
        if at(i + 2) == Some('u') && at(i + 3) == Some('{') {
            let k = (i + 4..i + 10).find(|&k| !hex(k)).unwrap_or(i + 10);
            if k > i + 4 && at(k) == Some('}') {
                ends.push(k + 1);
            }
        }
        if at(i + 2).is_some_and(|c| c != '\n') {
            ends.push(i + 3);
        }
        ends.into_iter().find(|&k| at(k) == Some('\'')).map(|k| k + 1)
    } else {
        let plain = at(i + 1).is_some_and(|c| !matches!(c, '\\' | '\'' | '\n'));
        (plain && at(i + 2) == Some('\'')).then_some(i + 3)
    }
}

/// The offset just after the bracket that closes the one at `open` (brackets of any kind nest).
fn matching(code: &[u8], open: usize) -> usize {
    let mut depth = 0usize;
    for (j, &c) in code.iter().enumerate().skip(open) {
        match c {
            b'(' | b'[' | b'{' => depth += 1,
            b')' | b']' | b'}' => {
                depth = depth.saturating_sub(1);
                if depth == 0 {
                    return j + 1;
                }
            }
            _ => {}
        }
    }
    code.len()
}

/// The end of the item that begins at `start`: its `;` outside brackets, or the `}` closing its body.
fn item_end(code: &[u8], start: usize) -> usize {
    let mut j = start;
    while j < code.len() {
        match code[j] {
            b';' => return j + 1,
            b'(' | b'[' => j = matching(code, j),
            b'{' => {
                let end = matching(code, j);
                let k = skip_space(code, end);
                return if code.get(k) == Some(&b';') { k + 1 } else { end };
            }
            _ => j += 1,
        }
    }
    code.len()
}

fn skip_space(code: &[u8], mut k: usize) -> usize {
    while k < code.len() && code[k].is_ascii_whitespace() {
        k += 1;
    }
    k
}

fn ident_end(code: &[u8], k: usize) -> usize {
    (k..code.len()).find(|&j| !is_ident(code[j])).unwrap_or(code.len())
}

fn find(code: &[u8], pattern: &[u8], from: usize) -> Option<usize> {
    code.get(from..)?.windows(pattern.len()).position(|w| w == pattern).map(|k| k + from)
}

fn blank_range(code: &mut [u8], range: std::ops::Range<usize>) {
    for c in &mut code[range] {
        if *c != b'\n' {
            *c = b' ';
        }
    }
}

/// (`code` with every `#[cfg(test)]` item blanked, the names of the `#[cfg(test)] mod name;` it declares).
fn strip_tests(mut code: Vec<u8>) -> (Vec<u8>, BTreeSet<String>) {
    let mut tests = BTreeSet::new();
    if find(&code, b"#![cfg(test)]", 0).is_some() {
        let len = code.len();
        blank_range(&mut code, 0..len);
        return (code, tests);
    }
    let mut done = 0;
    let mut from = 0;
    while let Some(at) = find(&code, b"#[cfg(test)]", from) {
        from = at + 1;
        if at < done {
            continue;
        }
        let mut j = at + b"#[cfg(test)]".len();
        loop {
            let k = skip_space(&code, j);
            if !code[k..].starts_with(b"#[") {
                break;
            }
            j = matching(&code, k + 1); // further attributes of the same item
        }
        let end = item_end(&code, j);
        if let Some(name) = mod_declaration(&String::from_utf8_lossy(&code[j..end])) {
            tests.insert(name);
        }
        blank_range(&mut code, at..end);
        done = end;
    }
    (code, tests)
}

/// The name of `[pub] mod name;`.
fn mod_declaration(item: &str) -> Option<String> {
    let mut rest = item.trim_start();
    if let Some(after) = rest.strip_prefix("pub") {
        let after = if after.starts_with('(') { &after[after.find(')')? + 1..] } else { after };
        if after.starts_with(char::is_whitespace) {
            rest = after.trim_start();
        }
    }
    let rest = rest.strip_prefix("mod")?;
    if !rest.starts_with(char::is_whitespace) {
        return None;
    }
    let rest = rest.trim_start();
    let name: String = rest.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
    (!name.is_empty() && rest[name.len()..].trim_start().starts_with(';')).then_some(name)
}

fn line_of(code: &[u8], offset: usize) -> usize {
    code[..offset].iter().filter(|&&c| c == b'\n').count() + 1
}

// ------------------------------------------------------------------------------------------------- paths

/// One file's paths: (offset, path as written, crate-absolute target), the names its `use`s bind, the modules it
/// imports with a glob.
struct Scan {
    code: Vec<u8>,
    refs: Vec<(usize, String, Module)>,
    aliases: BTreeMap<String, Module>,
    globs: Vec<Module>,
}

impl Scan {
    fn new(m: &Module, code: &[u8], mods: &BTreeSet<Module>) -> Scan {
        let mut code = code.to_vec();
        blank_restricted_visibility(&mut code);
        let inline = inline_mods(&code);
        let scope_at = |offset: usize| -> Module {
            let inner = inline.iter().filter(|(a, b, _)| *a < offset && offset < *b).map(|(_, _, name)| name.clone());
            m.iter().cloned().chain(inner).collect()
        };
        let mut scan = Scan { code: Vec::new(), refs: Vec::new(), aliases: BTreeMap::new(), globs: Vec::new() };
        let uses = uses(&code);
        for (start, _, body) in &uses {
            for (segs, name) in use_trees(body) {
                let Some(target) = absolute(&segs, &scope_at(*start), mods, &scan.aliases) else { continue };
                match name {
                    Some(name) => {
                        scan.aliases.insert(name, target.clone());
                    }
                    None => scan.globs.push(target.clone()),
                }
                scan.refs.push((*start, segs.join("::"), target));
            }
        }
        let mut rest = code.clone();
        for (start, end, _) in &uses {
            blank_range(&mut rest, *start..*end);
        }
        for (start, segs) in code_paths(&rest) {
            if let Some(target) = absolute(&segs, &scope_at(start), mods, &scan.aliases) {
                scan.refs.push((start, segs.join("::"), target));
            }
        }
        scan.code = code;
        scan
    }
}

/// Blanks `pub(in path)`: a visibility names no item.
fn blank_restricted_visibility(code: &mut [u8]) {
    let mut i = 0;
    while let Some(at) = find(code, b"pub", i) {
        i = at + 3;
        if at > 0 && is_ident(code[at - 1]) {
            continue;
        }
        let k = skip_space(code, at + 3);
        if code.get(k) != Some(&b'(') {
            continue;
        }
        let k = skip_space(code, k + 1);
        if !(code[k..].starts_with(b"in") && code.get(k + 2).is_some_and(u8::is_ascii_whitespace)) {
            continue;
        }
        if let Some(close) = find(code, b")", k) {
            blank_range(code, at..close + 1);
            i = close + 1;
        }
    }
}

/// (offset of `{`, offset after its `}`, name) of each inline `mod name { … }`.
fn inline_mods(code: &[u8]) -> Vec<(usize, usize, String)> {
    let mut out = Vec::new();
    let mut i = 0;
    while let Some(at) = find(code, b"mod", i) {
        i = at + 3;
        if (at > 0 && is_ident(code[at - 1])) || !code.get(at + 3).is_some_and(u8::is_ascii_whitespace) {
            continue;
        }
        let k = skip_space(code, at + 3);
        let end = ident_end(code, k);
        let open = skip_space(code, end);
        if end > k && code.get(open) == Some(&b'{') {
            out.push((open, matching(code, open), String::from_utf8_lossy(&code[k..end]).into_owned()));
            i = open + 1;
        }
    }
    out
}

/// (offset of `use`, offset after its `;`, the tree after `use`) of each `use` item.
fn uses(code: &[u8]) -> Vec<(usize, usize, String)> {
    let mut out = Vec::new();
    let mut i = 0;
    while let Some(at) = find(code, b"use", i) {
        i = at + 1;
        if (at > 0 && is_ident(code[at - 1])) || !code.get(at + 3).is_some_and(u8::is_ascii_whitespace) {
            continue;
        }
        if let Some(semi) = find(code, b";", at + 3) {
            out.push((at, semi + 1, String::from_utf8_lossy(&code[at + 3..semi]).into_owned()));
            i = semi + 1;
        }
    }
    out
}

/// The leaves of a `use` tree: (segments, the name bound, or `None` for a glob).
pub fn use_trees(body: &str) -> Vec<(Vec<String>, Option<String>)> {
    let b = body.as_bytes();
    let mut toks = Vec::new();
    let mut i = 0;
    while i < b.len() {
        if b[i..].starts_with(b"::") {
            toks.push("::".to_string());
            i += 2;
        } else if matches!(b[i], b'{' | b'}' | b',' | b'*') {
            toks.push((b[i] as char).to_string());
            i += 1;
        } else if is_ident(b[i]) {
            let end = ident_end(b, i);
            toks.push(body[i..end].to_string());
            i = end;
        } else {
            i += 1;
        }
    }
    let mut leaves = Vec::new();
    tree(&toks, 0, &[], &mut leaves);
    leaves.retain(|leaf| !leaf.0.is_empty());
    leaves
}

/// Reads the subtree of a `use` at token `i` under `prefix` into `leaves`; the token after it.
fn tree(toks: &[String], mut i: usize, prefix: &[String], leaves: &mut Vec<(Vec<String>, Option<String>)>) -> usize {
    let mut path = prefix.to_vec();
    while i < toks.len() {
        match toks[i].as_str() {
            "::" => i += 1,
            "{" => {
                i += 1;
                while i < toks.len() && toks[i] != "}" {
                    i = tree(toks, i, &path, leaves);
                    if toks.get(i).is_some_and(|t| t == ",") {
                        i += 1;
                    }
                }
                return i + 1;
            }
            "*" => {
                leaves.push((path, None));
                return i + 1;
            }
            "," | "}" => break,
            word => {
                path.push(word.to_string());
                i += 1;
                if i + 1 < toks.len() && toks[i] == "as" {
                    if path.last().is_some_and(|p| p == "self") {
                        path.pop();
                    }
                    leaves.push((path, Some(toks[i + 1].clone())));
                    return i + 2;
                }
                if toks.get(i).is_some_and(|t| t == "::") {
                    continue;
                }
                if path.last().is_some_and(|p| p == "self") {
                    path.pop();
                }
                let name = path.last().cloned();
                leaves.push((path, name));
                return i;
            }
        }
    }
    i
}

/// (offset, segments) of every path of two segments or more (`a::b`, `crate::a::b`) in `code`.
fn code_paths(code: &[u8]) -> Vec<(usize, Vec<String>)> {
    let word = |a: usize, b: usize| String::from_utf8_lossy(&code[a..b]).into_owned();
    let mut out = Vec::new();
    let mut i = 0;
    while i < code.len() {
        if !is_ident(code[i]) || (i > 0 && (is_ident(code[i - 1]) || code[i - 1] == b':')) {
            i += 1;
            continue;
        }
        let mut end = ident_end(code, i);
        let mut segs = vec![word(i, end)];
        loop {
            let k = skip_space(code, end);
            if !code[k..].starts_with(b"::") {
                break;
            }
            let k = skip_space(code, k + 2);
            if k >= code.len() || !is_ident(code[k]) {
                break;
            }
            end = ident_end(code, k);
            segs.push(word(k, end));
        }
        if segs.len() > 1 {
            out.push((i, segs));
        }
        i = end;
    }
    out
}

/// The crate-absolute module path `segs` stands for in `scope`, or `None` for a path outside the crate
/// (`std::…`, `glam::…`, `Self::…`).
fn absolute(
    segs: &[String],
    scope: &[String],
    mods: &BTreeSet<Module>,
    aliases: &BTreeMap<String, Module>,
) -> Option<Module> {
    let head = segs.first()?.as_str();
    let rest = |k: usize| segs[k..].iter().cloned();
    match head {
        "crate" => Some(rest(1).collect()),
        "super" | "self" => {
            let mut base = scope.to_vec();
            let k = segs.iter().take_while(|s| *s == "super" || *s == "self").count();
            for s in &segs[..k] {
                if s == "super" {
                    base.pop();
                }
            }
            Some(base.into_iter().chain(rest(k)).collect())
        }
        _ if mods.contains(&[scope, &segs[..1]].concat()) => Some(scope.iter().cloned().chain(rest(0)).collect()),
        _ => aliases.get(head).map(|a| a.iter().cloned().chain(rest(1)).collect()),
    }
}

/// The longest prefix of `target` that is a module file (the crate root when none is).
fn resolve(mods: &BTreeSet<Module>, target: &[String]) -> Option<Module> {
    (0..=target.len()).rev().map(|k| target[..k].to_vec()).find(|p| mods.contains(p))
}

/// Whether `code` defines an item called `name` itself.
fn defines(code: &[u8], name: &str) -> bool {
    const KEYWORDS: [&[u8]; 9] = [b"fn", b"struct", b"enum", b"union", b"trait", b"type", b"const", b"static", b"mod"];
    let name = name.as_bytes();
    let mut from = 0;
    while let Some(at) = find(code, name, from) {
        from = at + 1;
        if code.get(at + name.len()).is_some_and(|&c| is_ident(c)) {
            continue;
        }
        let mut k = at;
        while k > 0 && code[k - 1].is_ascii_whitespace() {
            k -= 1;
        }
        let mut s = k;
        while s > 0 && is_ident(code[s - 1]) {
            s -= 1;
        }
        if k < at && KEYWORDS.contains(&&code[s..k]) {
            return true;
        }
        let m = b"macro_rules!";
        if k >= m.len() && code[..k].ends_with(m) && (k == m.len() || !is_ident(code[k - m.len() - 1])) {
            return true;
        }
    }
    false
}

/// The file that defines what `target` names: the longest prefix that is a module file, then, when that file does
/// not define the next name itself but brings it in with a `use` (`pub use child::X`, `pub use types::*`), the
/// file it comes from.
fn locate(
    mods: &BTreeSet<Module>,
    scans: &BTreeMap<Module, Scan>,
    target: &[String],
    seen: &mut BTreeSet<(Module, String)>,
) -> Option<Module> {
    let file = resolve(mods, target)?;
    let Some(name) = target.get(file.len()) else { return Some(file) };
    let rest = &target[file.len() + 1..];
    let scan = &scans[&file];
    if defines(&scan.code, name) || !seen.insert((file.clone(), name.clone())) {
        return Some(file);
    }
    if let Some(from) = scan.aliases.get(name) {
        return locate(mods, scans, &[from.as_slice(), rest].concat(), seen);
    }
    for glob in &scan.globs {
        if scans.get(glob).is_some_and(|g| defines(&g.code, name) || g.aliases.contains_key(name)) {
            return locate(mods, scans, &[glob.as_slice(), std::slice::from_ref(name), rest].concat(), seen);
        }
    }
    Some(file)
}
