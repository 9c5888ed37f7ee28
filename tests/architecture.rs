//! The import graph of every crate's modules has no circle (ARCHITECTURE.md): no module uses
//! one that uses it back, directly or through others. Read from the source as text: every
//! `crate::`, `super::` and `self::` path (in `use` lines and inline), and a `use` of a child
//! module by its bare name, resolved to the file of the longest module path that exists; the
//! part of a file from `#[cfg(test)]` on is left out (unit tests may reach anywhere). A module
//! naming one of its own ancestors is not an arrow: a child module is part of its parent (it
//! sees the parent's private items, and often holds more of the parent's own types' methods,
//! as `neighbour::images` does for `NeighbourList`); every other circle, between siblings,
//! cousins or through a parent's children, is one.
//!
//! And the project cites nothing outside itself: no source, study, script or doc names the
//! model's old out-of-tree spec or a path beside the repository (the spec is docs/model.md).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use crate::common;
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
        let files = std::fs::read_dir(&src).expect("src").count();
        if files == 1 {
            // One module (lib.rs alone): nothing to circle.
            checked += 1;
            continue;
        }
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
    let crates = library_crates().len() + 1;
    assert!(crates >= 9, "only {crates} crates found");
    assert_eq!(checked, crates, "every crate of the workspace");
}

/// The workflows (study, reproduce, fidelity, accuracy) take plain option structs, so that a
/// library caller runs them without clap: only the command line (`cli`) and the dispatch
/// from it (`commands`) know the clap structs.
#[test]
fn only_the_command_line_knows_the_clap_structs() {
    let graph = graph_of(&repo().join("crates/hvi-study/src"));
    let cli = vec!["cli".to_string()];
    assert!(graph.contains_key(&cli), "no `cli` module read");
    let users: Vec<String> = graph
        .iter()
        .filter(|(m, deps)| {
            deps.contains(&cli)
                && !matches!(m.first().map(String::as_str), Some("cli" | "commands"))
        })
        .map(|(m, _)| show(std::slice::from_ref(m)))
        .collect();
    assert!(
        users.is_empty(),
        "workflow modules that import the clap structs of `cli` (give them an options struct \
         that `cli` builds): {users:?}"
    );
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

/// Where the sources and docs are: directories searched recursively, and single files.
const CITING_DIRS: [&str; 8] = [
    "crates",
    "tests",
    "docs",
    "studies",
    "experiments_data",
    "bench",
    "scripts",
    ".ci",
];
const CITING_FILES: [&str; 2] = ["README.md", "ARCHITECTURE.md"];

/// Every file under `dir` whose name ends in one of the extensions (or has none, for the
/// scripts of `.ci`), skipping build output.
fn sources_under(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries {
        let path = entry.expect("entry").path();
        if path.is_dir() {
            if path.file_name().is_some_and(|n| n == "target") {
                continue;
            }
            sources_under(&path, out);
        } else {
            let ext = path.extension().and_then(|e| e.to_str());
            if matches!(ext, Some("rs" | "md" | "toml" | "sh") | None) {
                out.push(path);
            }
        }
    }
}

/// The lines `matcher` finds in each of `files` (text files; others skipped), as
/// `path:line: text` with the path relative to `root`.
fn matching_lines(
    root: &Path,
    files: &[PathBuf],
    matcher: fn(&str) -> Vec<(usize, String)>,
) -> Vec<String> {
    let mut found = Vec::new();
    for path in files {
        let Ok(text) = std::fs::read_to_string(path) else {
            continue; // not text
        };
        for (n, line) in matcher(&text) {
            let rel = path.strip_prefix(root).unwrap_or(path);
            found.push(format!("{}:{n}: {line}", rel.display()));
        }
    }
    found
}

/// The citations of a path outside the repository in `text`, as (line number, line).
fn outside_citations(text: &str) -> Vec<(usize, String)> {
    // Spelled in pieces so that this file does not cite them itself.
    let needles = [concat!("MODEL", ".md"), concat!("../", "shared")];
    text.lines()
        .enumerate()
        .filter(|(_, line)| needles.iter().any(|n| line.contains(n)))
        .map(|(i, line)| (i + 1, line.trim().to_string()))
        .collect()
}

#[test]
fn no_source_or_doc_cites_a_path_outside_the_repository() {
    let root = repo();
    let mut files = Vec::new();
    for dir in CITING_DIRS {
        sources_under(&root.join(dir), &mut files);
    }
    files.extend(CITING_FILES.iter().map(|f| root.join(f)));
    assert!(files.len() > 100, "only {} files found", files.len());
    let found = matching_lines(&root, &files, outside_citations);
    assert!(
        found.is_empty(),
        "cite docs/model.md (and its section) instead of a path outside the repository:\n{}",
        found.join("\n")
    );
    // The check itself finds what it is for.
    let bad = format!(
        "see {} section 5 in {}/",
        concat!("MODEL", ".md"),
        concat!("../", "shared")
    );
    assert_eq!(outside_citations(&bad).len(), 1);
    assert!(outside_citations("see docs/model.md section 5").is_empty());
}

/// The command's crate: the only one that prints and the only one that uses `anyhow`.
const COMMAND_CRATE: &str = "hvi-study";

/// Every library crate's directory (every crate of `crates/` but the command's).
fn library_crates() -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(repo().join("crates"))
        .expect("crates/")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.join("Cargo.toml").is_file() && !p.ends_with(COMMAND_CRATE))
        .collect();
    out.sort();
    out
}

/// The lines of `text` outside its `#[cfg(test)]` module that print to the terminal, as (line
/// number, line). Comments do not count.
fn prints(text: &str) -> Vec<(usize, String)> {
    // Spelled in pieces so that this file does not match itself.
    let macros = [
        concat!("println", "!("),
        concat!("eprintln", "!("),
        concat!("print", "!("),
        concat!("eprint", "!("),
        concat!("dbg", "!("),
        // Writing to the standard streams by hand is printing too.
        concat!("stdout", "()"),
        concat!("stderr", "().lock("),
    ];
    text.lines()
        .enumerate()
        .take_while(|(_, line)| line.trim() != "#[cfg(test)]")
        .filter(|(_, line)| !line.trim_start().starts_with("//"))
        .filter(|(_, line)| {
            macros.iter().any(|m| {
                line.match_indices(m).any(|(i, _)| {
                    // `print!(` inside `eprint!(` or `println!(` counts once, as itself.
                    !line[..i].ends_with(|c: char| c.is_alphanumeric() || c == '_')
                })
            })
        })
        .map(|(i, line)| (i + 1, line.trim().to_string()))
        .collect()
}

#[test]
fn library_crates_never_print() {
    let root = repo();
    let mut files = Vec::new();
    for dir in library_crates() {
        sources_under(&dir.join("src"), &mut files);
    }
    files.retain(|p| p.extension().is_some_and(|e| e == "rs"));
    let found = matching_lines(&root, &files, prints);
    assert!(
        files.len() > 40,
        "only {} library sources found",
        files.len()
    );
    assert!(
        found.is_empty(),
        "a library prints; report through the log facade (log::info!, log::warn!) and let \
         the binary print:\n{}",
        found.join("\n")
    );
    // The check itself finds what it is for, and leaves comments and tests alone.
    let sample = format!(
        "fn f() {{\n    {}\"x\");\n    // {}\"y\");\n}}\n#[cfg(test)]\nmod tests {{ fn g() {{ {}\"z\"); }} }}\n",
        concat!("eprintln", "!("),
        concat!("println", "!("),
        concat!("println", "!("),
    );
    assert_eq!(prints(&sample).len(), 1, "{sample}");
    let by_hand = format!(
        "fn f() {{\n    let mut e = std::io::{}; let _ = writeln!(e, \"x\");\n    let t = std::io::{}().is_terminal();\n}}\n",
        concat!("stderr", "().lock()"),
        "stderr",
    );
    assert_eq!(prints(&by_hand).len(), 1, "{by_hand}");
}

/// Every module of a crate's `src`, as its path under `src` without `.rs` or `/mod.rs`
/// (`study/calibrate/ego`), the crate roots left out.
fn module_paths(src: &Path) -> Vec<String> {
    let mut files = Vec::new();
    sources_under(src, &mut files);
    files
        .iter()
        .filter(|p| p.extension().is_some_and(|e| e == "rs"))
        .filter_map(|p| {
            let rel = p
                .strip_prefix(src)
                .ok()?
                .to_string_lossy()
                .replace('\\', "/");
            let rel = rel.strip_suffix(".rs")?;
            let rel = rel.strip_suffix("/mod").unwrap_or(rel);
            (!matches!(rel, "lib" | "main")).then(|| rel.to_string())
        })
        .collect()
}

#[test]
fn architecture_md_names_every_module() {
    let root = repo();
    let text = std::fs::read_to_string(root.join("ARCHITECTURE.md")).expect("ARCHITECTURE.md");
    let mut missing = Vec::new();
    let mut count = 0;
    let crates = library_crates()
        .into_iter()
        .chain([root.join("crates").join(COMMAND_CRATE)]);
    for dir in crates {
        let krate = dir
            .file_name()
            .expect("a crate's name")
            .to_string_lossy()
            .into_owned();
        for m in module_paths(&dir.join("src")) {
            count += 1;
            // Named as `a::b::c`, or as `c` inside its parent's row (`sim::band`,
            // `stages::shared`, `render::side`).
            let full = m.replace('/', "::");
            let last = m.rsplit('/').next().unwrap_or(&m);
            let parent = m.rsplit('/').nth(1);
            let named = text.contains(&format!("`{full}`"))
                || parent.is_some_and(|p| text.contains(&format!("`{p}::{last}`")))
                || (parent.is_none() && text.contains(&format!("| `{last}` |")))
                || (parent.is_some() && text.contains(&format!("`{last}`")));
            if !named {
                missing.push(format!("{krate}: {full}"));
            }
        }
    }
    assert!(count > 80, "only {count} modules found");
    assert!(
        missing.is_empty(),
        "ARCHITECTURE.md does not name these modules:\n{}",
        missing.join("\n")
    );
}

/// The `[dependencies]` table of a crate's manifest, as the names it lists.
fn dependencies(manifest: &str) -> Vec<String> {
    let mut names = Vec::new();
    let mut inside = false;
    for line in manifest.lines() {
        let line = line.trim();
        if line.starts_with('[') {
            inside = line == "[dependencies]";
        } else if inside && !line.is_empty() && !line.starts_with('#') {
            if let Some((name, _)) = line.split_once(['=', '.']) {
                names.push(name.trim().to_string());
            }
        }
    }
    names
}

#[test]
fn library_crates_return_typed_errors_and_only_the_command_uses_anyhow_clap_and_bars() {
    let crates = library_crates();
    assert!(
        crates.len() >= 8,
        "only {} library crates found",
        crates.len()
    );
    let mut found = Vec::new();
    for dir in &crates {
        let manifest = std::fs::read_to_string(dir.join("Cargo.toml")).expect("manifest");
        let deps = dependencies(&manifest);
        for only_the_command in ["anyhow", "clap", "indicatif"] {
            if deps.iter().any(|d| d == only_the_command) {
                found.push(format!("{}: depends on {only_the_command}", dir.display()));
            }
        }
        // Its own typed error, or the one of the crate below it that it returns (hvi-run's
        // RunError for the store and the workflows, hvi-scene's EngineError for the engine).
        if !deps
            .iter()
            .any(|d| d == "thiserror" || d == "hvi-run" || d == "hvi-scene")
        {
            found.push(format!(
                "{}: neither defines a typed error (thiserror) nor returns a lower crate's",
                dir.display()
            ));
        }
    }
    assert!(found.is_empty(), "{}", found.join("\n"));
    // The reader finds what it is for.
    let sample = "[package]\nname = \"x\"\n[dependencies]\nanyhow.workspace = true\nserde = \"1\"\n[dev-dependencies]\nproptest = \"1\"\n";
    assert_eq!(dependencies(sample), ["anyhow", "serde"]);
}

/// The longest a function outside tests may be, in lines from its `fn` line to its closing
/// brace (a reader holds it at once).
const LONGEST_FUNCTION: usize = 80;

/// The functions of `text` (outside its `#[cfg(test)]` module) longer than
/// [`LONGEST_FUNCTION`], as (line of the `fn`, name and length). A function is read from a line
/// whose code starts with `fn` (after `pub`, `pub(crate)`, `const`, `unsafe`) to the first line
/// that is its indentation and `}`.
fn long_functions(text: &str) -> Vec<(usize, String)> {
    let lines: Vec<&str> = text
        .lines()
        .take_while(|l| l.trim() != "#[cfg(test)]")
        .collect();
    let mut found = Vec::new();
    for (i, line) in lines.iter().enumerate() {
        let code = line.trim_start();
        let indent = &line[..line.len() - code.len()];
        let mut rest = code;
        for prefix in ["pub(crate) ", "pub(super) ", "pub ", "const ", "unsafe "] {
            rest = rest.strip_prefix(prefix).unwrap_or(rest);
        }
        let Some(sig) = rest.strip_prefix("fn ") else {
            continue;
        };
        if line.trim_end().ends_with(';') {
            continue; // a declaration in a trait
        }
        let close = format!("{indent}}}");
        let Some(end) = lines[i..].iter().position(|l| l.trim_end() == close) else {
            continue;
        };
        let n = end + 1;
        if n > LONGEST_FUNCTION {
            let name: String = sig
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            found.push((i + 1, format!("fn {name}: {n} lines")));
        }
    }
    found
}

#[test]
fn no_function_is_longer_than_a_reader_holds() {
    let root = repo();
    let mut files = Vec::new();
    sources_under(&root.join("crates"), &mut files);
    files.retain(|p| {
        p.extension().is_some_and(|e| e == "rs") && p.components().any(|c| c.as_os_str() == "src")
    });
    assert!(files.len() > 100, "only {} sources found", files.len());
    let found = matching_lines(&root, &files, long_functions);
    assert!(
        found.is_empty(),
        "functions over {LONGEST_FUNCTION} lines (split them into named steps):\n{}",
        found.join("\n")
    );
    // The reader finds what it is for, and leaves tests alone.
    let body = "    let x = 1;\n".repeat(LONGEST_FUNCTION);
    let long = format!(
        "pub fn f() {{\n{body}}}\n#[cfg(test)]\nmod tests {{\n    fn g() {{\n{body}    }}\n}}\n"
    );
    assert_eq!(long_functions(&long).len(), 1, "{long}");
    let short = format!(
        "fn f() {{\n{}}}\n",
        "    let x = 1;\n".repeat(LONGEST_FUNCTION - 2)
    );
    assert!(long_functions(&short).is_empty());
}
