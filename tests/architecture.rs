//! The import graph of every crate's modules has no circle (ARCHITECTURE.md): no module uses
//! one that uses it back, directly or through others. Read from the source as text: every
//! `crate::`, `super::` and `self::` path (in `use` lines and inline), and a `use` of a child
//! module by its bare name, resolved to the file of the longest module path that exists; the
//! part of a file from `#[cfg(test)]` on is left out (unit tests may reach anywhere). A module
//! naming one of its own ancestors is not an arrow: a child module is part of its parent (it
//! sees the parent's private items, and often holds more of the parent's own types' methods,
//! as `neighbour::images` does for `NeighbourList`); every other circle, between siblings,
//! cousins or through a parent's children, is one.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

mod common;
use common::repo;

/// A module path (segments below the crate root) and the file that holds it.
type Modules = BTreeMap<Vec<String>, PathBuf>;

/// Every module file of a crate's `src` (not the binary's `main.rs`), by module path.
fn modules(src: &Path) -> Modules {
    fn walk(dir: &Path, prefix: &[String], out: &mut Modules) {
        let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
            .expect("src dir")
            .map(|e| e.expect("entry").path())
            .collect();
        entries.sort();
        for path in entries {
            let name = path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
            if path.is_dir() {
                let mut p = prefix.to_vec();
                p.push(
                    path.file_name()
                        .expect("name")
                        .to_string_lossy()
                        .into_owned(),
                );
                walk(&path, &p, out);
            } else if path.extension().is_some_and(|e| e == "rs") {
                let module = match name.as_str() {
                    "lib" if prefix.is_empty() => Vec::new(),
                    "main" if prefix.is_empty() => continue,
                    "mod" => prefix.to_vec(),
                    _ => {
                        let mut p = prefix.to_vec();
                        p.push(name);
                        p
                    }
                };
                out.insert(module, path);
            }
        }
    }
    let mut out = Modules::new();
    walk(src, &[], &mut out);
    out
}

/// The longest prefix of `path` that is a module.
fn resolve(modules: &Modules, path: &[String]) -> Option<Vec<String>> {
    (0..=path.len())
        .rev()
        .map(|n| path[..n].to_vec())
        .find(|p| modules.contains_key(p))
}

/// The modules one module's code names, by the rules of the file's doc.
fn imports(modules: &Modules, module: &[String], text: &str) -> BTreeSet<Vec<String>> {
    let code = text.split("#[cfg(test)]").next().unwrap_or("");
    let mut out = BTreeSet::new();
    let ident = |c: char| c.is_ascii_alphanumeric() || c == '_';
    for line in code.lines() {
        let line = line.split("//").next().unwrap_or("");
        // Every `crate::a::b`, `super::a`, `self::a` path on the line, and `{a, b::c}` groups
        // are followed only to their first segment (enough to find the module).
        for (start, _) in line.match_indices("::") {
            let head_start = line[..start]
                .rfind(|c: char| !ident(c))
                .map_or(0, |i| i + 1);
            let head = &line[head_start..start];
            if head_start > 0 && line[..head_start].ends_with("::") {
                continue; // inside a longer path, counted from its head
            }
            let mut base: Vec<String> = match head {
                "crate" => Vec::new(),
                "super" => module[..module.len().saturating_sub(1)].to_vec(),
                "self" => module.to_vec(),
                _ => {
                    // A child module named bare in a `use` line.
                    let trimmed = line.trim_start();
                    let is_use = trimmed.starts_with("use ") || trimmed.starts_with("pub use ");
                    let mut child = module.to_vec();
                    child.push(head.to_string());
                    if is_use
                        && head_start == line.find(head).unwrap_or(usize::MAX)
                        && modules.contains_key(&child)
                    {
                        module.to_vec()
                    } else {
                        continue;
                    }
                }
            };
            let rest = &line[start + 2..];
            let mut tail = rest;
            if !matches!(head, "crate" | "super" | "self") {
                base.push(head.to_string());
            }
            // `super::super::x`
            while let Some(r) = tail.strip_prefix("super::") {
                base.pop();
                tail = r;
            }
            for seg in tail.split("::") {
                let seg: String = seg.chars().take_while(|&c| ident(c)).collect();
                if seg.is_empty() {
                    break;
                }
                base.push(seg);
            }
            if let Some(m) = resolve(modules, &base) {
                let ancestor = m.len() < module.len() && module[..m.len()] == m[..];
                if m != module && !ancestor {
                    out.insert(m);
                }
            }
        }
    }
    out
}

/// A circle of the graph, if there is one (as the modules around it).
fn circle(graph: &BTreeMap<Vec<String>, BTreeSet<Vec<String>>>) -> Option<Vec<Vec<String>>> {
    #[derive(Clone, Copy, PartialEq)]
    enum Mark {
        New,
        Open,
        Done,
    }
    fn visit(
        n: &Vec<String>,
        graph: &BTreeMap<Vec<String>, BTreeSet<Vec<String>>>,
        mark: &mut BTreeMap<Vec<String>, Mark>,
        stack: &mut Vec<Vec<String>>,
    ) -> Option<Vec<Vec<String>>> {
        mark.insert(n.clone(), Mark::Open);
        stack.push(n.clone());
        for m in graph.get(n).into_iter().flatten() {
            match mark.get(m).copied().unwrap_or(Mark::New) {
                Mark::Open => {
                    let at = stack.iter().position(|s| s == m).unwrap_or(0);
                    let mut c = stack[at..].to_vec();
                    c.push(m.clone());
                    return Some(c);
                }
                Mark::New => {
                    if let Some(c) = visit(m, graph, mark, stack) {
                        return Some(c);
                    }
                }
                Mark::Done => {}
            }
        }
        stack.pop();
        mark.insert(n.clone(), Mark::Done);
        None
    }
    let mut mark = BTreeMap::new();
    for n in graph.keys() {
        if mark.get(n).copied().unwrap_or(Mark::New) == Mark::New {
            if let Some(c) = visit(n, graph, &mut mark, &mut Vec::new()) {
                return Some(c);
            }
        }
    }
    None
}

/// The import graph of the crate whose sources are in `src`.
fn graph_of(src: &Path) -> BTreeMap<Vec<String>, BTreeSet<Vec<String>>> {
    let modules = modules(src);
    modules
        .iter()
        .map(|(m, path)| {
            let text = std::fs::read_to_string(path).expect("source");
            (m.clone(), imports(&modules, m, &text))
        })
        .collect()
}

fn show(c: &[Vec<String>]) -> String {
    c.iter()
        .map(|m| {
            if m.is_empty() {
                "crate".to_string()
            } else {
                m.join("::")
            }
        })
        .collect::<Vec<_>>()
        .join(" -> ")
}

#[test]
fn no_module_imports_one_that_imports_it_back() {
    let crates = repo().join("crates");
    let mut checked = 0;
    for entry in std::fs::read_dir(&crates).expect("crates") {
        let src = entry.expect("crate").path().join("src");
        if !src.is_dir() {
            continue;
        }
        let graph = graph_of(&src);
        assert!(graph.len() > 1, "{}: no modules read", src.display());
        let edges: usize = graph.values().map(BTreeSet::len).sum();
        assert!(edges > 0, "{}: no imports read", src.display());
        // Every circle, one at a time: the edge that closes each is set aside to find the next.
        let mut g = graph.clone();
        let mut found = Vec::new();
        while let Some(c) = circle(&g) {
            found.push(show(&c));
            let (a, b) = (&c[c.len() - 2], &c[c.len() - 1]);
            g.get_mut(a).expect("node").remove(b);
        }
        assert!(
            found.is_empty(),
            "circles of imports in {}:\n{}",
            src.display(),
            found.join("\n")
        );
        checked += 1;
    }
    assert_eq!(checked, 5, "the workspace's five crates");
}

#[test]
fn a_circle_is_found_through_use_lines_inline_paths_and_parents() {
    let dir = common::scratch("hvi-architecture", "circle");
    let src = dir.join("src");
    std::fs::create_dir_all(src.join("a")).expect("dirs");
    let write = |p: &str, t: &str| std::fs::write(src.join(p), t).expect("write");
    write("lib.rs", "pub mod a;\npub mod b;\n");
    // a's mod.rs uses its child c by its bare name; c reaches b inline; b uses a.
    write("a/mod.rs", "pub mod c;\nuse c::thing;\n");
    write(
        "a/c.rs",
        "pub fn thing() { crate::b::other(); super::helper(); }\n",
    );
    write("b.rs", "use crate::a::helper;\npub fn other() {}\n");
    let graph = graph_of(&src);
    let c = circle(&graph).unwrap_or_else(|| panic!("no circle in {graph:?}"));
    assert_eq!(show(&c), "a -> a::c -> b -> a");
    // Without the way back, no circle: c naming its own parent is not an arrow, and b's test
    // module does not count.
    write(
        "b.rs",
        "pub fn other() {}\n#[cfg(test)]\nmod tests { use crate::a; }\n",
    );
    let graph = graph_of(&src);
    assert!(circle(&graph).is_none(), "{graph:?}");
    assert!(graph[&vec!["b".to_string()]].is_empty(), "{graph:?}");
    assert_eq!(
        graph[&vec!["a".to_string(), "c".to_string()]].len(),
        1,
        "{graph:?}"
    );
}
