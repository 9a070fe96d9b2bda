//! core's modules form the layers of the table "Core's layers" in docs/ARCHITECTURE.md (the order of the data
//! flow): each module's code names only modules listed above it, so there is no import cycle between them, and
//! every module of `lib.rs` has its place in the table. Inside the modules, no file names a file that names it
//! back, through any chain of files (the graph of `layers`, which `tools/structure.py` draws too). Test modules
//! and comments are not counted.

#![allow(clippy::unwrap_used)]

mod layers;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The top-level modules that `lib.rs` declares, sorted.
fn declared(src: &Path) -> Vec<String> {
    let lib = std::fs::read_to_string(src.join("lib.rs")).unwrap();
    let mut mods: Vec<String> = lib
        .lines()
        .filter_map(|l| l.trim().strip_prefix("pub mod ").and_then(|r| r.strip_suffix(';')))
        .map(str::to_string)
        .collect();
    mods.sort();
    mods
}

/// The modules in the order of the layer table of docs/ARCHITECTURE.md (first column, in backticks).
fn layers(page: &str) -> Vec<String> {
    let section = page.split("## Core's layers").nth(1).unwrap_or("");
    let section = section.split("\n## ").next().unwrap_or("");
    section
        .lines()
        .filter_map(|l| l.strip_prefix("| `"))
        .filter_map(|l| l.split('`').next())
        .map(str::to_string)
        .collect()
}

/// The source files of a module: `name.rs`, or every file under `name/`.
fn files(src: &Path, name: &str) -> Vec<PathBuf> {
    let file = src.join(format!("{name}.rs"));
    if file.exists() {
        return vec![file];
    }
    let mut out = Vec::new();
    let mut stack = vec![src.join(name)];
    while let Some(dir) = stack.pop() {
        for e in std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

/// The top-level modules named as `crate::name` in the non-test, non-comment code of `text`.
fn uses(text: &str, modules: &[String]) -> Vec<String> {
    let mut found = Vec::new();
    for line in text.lines().take_while(|l| !l.starts_with("#[cfg(test)]")) {
        let code = line.split("//").next().unwrap_or("");
        let mut rest = code;
        while let Some(i) = rest.find("crate::") {
            rest = &rest[i + "crate::".len()..];
            let names: Vec<&str> = match rest.strip_prefix('{') {
                Some(group) => group.split('}').next().unwrap_or("").split(',').collect(),
                None => vec![rest],
            };
            for n in names {
                let n: String = n.trim().chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
                if modules.contains(&n) && !found.contains(&n) {
                    found.push(n);
                }
            }
        }
    }
    found
}

#[test]
fn each_module_uses_only_the_modules_declared_before_it() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let page = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/ARCHITECTURE.md")).unwrap();
    let order = layers(&page);
    let mut listed = order.clone();
    listed.sort();
    assert_eq!(listed, declared(&src), "docs/ARCHITECTURE.md's layer table and lib.rs list different modules");
    let rank: BTreeMap<&str, usize> = order.iter().enumerate().map(|(i, m)| (m.as_str(), i)).collect();
    let mut violations = Vec::new();
    for (i, module) in order.iter().enumerate() {
        for file in files(&src, module) {
            let text = std::fs::read_to_string(&file).unwrap();
            for used in uses(&text, &order) {
                if rank[used.as_str()] >= i && used != *module {
                    violations.push(format!("{} ({module}) uses crate::{used}", file.display()));
                }
            }
        }
    }
    assert!(
        violations.is_empty(),
        "modules that use a module listed after them in docs/ARCHITECTURE.md:\n{}",
        violations.join("\n")
    );
}

#[test]
fn the_scanner_sees_grouped_and_plain_paths() {
    let modules = vec!["math".to_string(), "scene".to_string(), "render".to_string()];
    let text = "use crate::math::Ray;\nuse crate::{scene, render::x};\n// crate::nothing\n#[cfg(test)]\nuse crate::y;";
    assert_eq!(uses(text, &modules), ["math", "scene", "render"]);
}

#[test]
fn no_file_of_core_names_a_file_that_names_it_back() {
    let cycles = layers::crate_cycles(&Path::new(env!("CARGO_MANIFEST_DIR")).join("src"));
    assert!(
        cycles.is_empty(),
        "import cycles between core's files (python3 tools/structure.py --why shows them too):\n{}",
        cycles.join("\n")
    );
}

#[test]
fn the_file_graph_follows_uses_paths_and_re_exports() {
    let files = [
        ("lib.rs", "pub mod a;\npub mod b;\nmod c;\n#[cfg(test)]\nmod tests;\n"),
        (
            "a/mod.rs",
            "//! [`crate::c::nothing`]\npub mod x;\npub mod y;\npub use y::*;\nuse crate::{b::{self, Thing as T}, c};\n\
             fn f() -> &'static str { x::g(); \"crate::c::h {\" }\n#[cfg(test)]\nmod tests {\n    use crate::c::z;\n}\n",
        ),
        (
            "a/x.rs",
            "use super::Item;\npub fn g() {\n    self::inner::k();\n    super::super::b::f();\n}\n\
             mod inner {\n    pub fn k() {\n        super::g();\n    }\n}\n",
        ),
        ("a/y.rs", "pub struct Item;\npub fn h() -> char {\n    crate::a::x::g();\n    '{'\n}\n"),
        ("b.rs", "pub struct Thing;\npub fn f() {}\npub(in crate::a) fn q() {}\n"),
        ("c.rs", "pub fn h() {}\n"),
        ("tests.rs", "use crate::a::x::g;\n"),
    ];
    let sources: Vec<(String, String)> = files.iter().map(|(p, t)| (p.to_string(), t.to_string())).collect();
    let graph = layers::graph(&sources);
    let named: BTreeMap<&str, BTreeSet<&str>> =
        graph.iter().map(|(f, to)| (f.as_str(), to.keys().map(String::as_str).collect())).collect();
    let expected: BTreeMap<&str, BTreeSet<&str>> = [
        ("lib.rs", vec![]),
        ("a/mod.rs", vec!["a/x.rs", "a/y.rs", "b.rs", "c.rs"]),
        ("a/x.rs", vec!["a/y.rs", "b.rs"]),
        ("a/y.rs", vec!["a/x.rs"]),
        ("b.rs", vec![]),
        ("c.rs", vec![]),
    ]
    .into_iter()
    .map(|(f, to)| (f, to.into_iter().collect()))
    .collect();
    assert_eq!(named, expected);
    assert_eq!(graph["a/x.rs"]["a/y.rs"], [(1, "super::Item".to_string())]);
    assert_eq!(layers::cycles(&graph), [["a/x.rs", "a/y.rs", "a/x.rs"]]);
}
