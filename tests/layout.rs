//! The library's layers (docs/layout.md): production code imports only from lower layers, and
//! no two files of the library import each other, directly or around a circle.
//!
//! The test reads the layers from docs/layout.md's table, so the page and the code cannot drift
//! apart, and the imports from the sources: every `crate::` path and every `super::` /
//! `self::` path in code outside comments and outside test-only code (a `#[cfg(test)]` module,
//! inline or in its own file). A file's edges to its ancestor modules' files (the folder's
//! interface) are not counted as circles.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Circles that are known and owed: each names the issue item that removes it. None is left;
/// `the_circle_search_finds_every_circle_and_no_other` shows that the search still works.
const KNOWN_CIRCLES: &[&[&str]] = &[];

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Layer of each top-level module, from the table under "## Layers" in docs/layout.md: rows
/// `| N | `a`, `b` | ... |`.
fn layers() -> BTreeMap<String, usize> {
    let page = std::fs::read_to_string(root().join("docs/layout.md")).expect("docs/layout.md");
    let section = page
        .split("## Layers")
        .nth(1)
        .expect("docs/layout.md has a '## Layers' section");
    let mut layers = BTreeMap::new();
    for line in section.lines().take_while(|l| !l.starts_with("## ")) {
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        let Some(layer) = cells.get(1).and_then(|c| c.parse::<usize>().ok()) else {
            continue;
        };
        for name in cells[2].split(',') {
            let name = name.trim().trim_matches('`');
            layers.insert(name.to_string(), layer);
        }
    }
    assert!(layers.len() >= 10, "layers not found in docs/layout.md");
    layers
}

/// Module path of a source file: `src/fit/bayes/mcmc.rs` -> `[fit, bayes, mcmc]`,
/// `src/fit/mod.rs` -> `[fit]`.
fn module_path(file: &Path) -> Vec<String> {
    let relative = file.strip_prefix(root().join("src")).unwrap();
    let mut parts: Vec<String> = relative
        .iter()
        .map(|p| p.to_string_lossy().trim_end_matches(".rs").to_string())
        .collect();
    if parts.last().map(String::as_str) == Some("mod") {
        parts.pop();
    }
    parts
}

/// The file of the module `path`, if it is one.
fn file_of(path: &[String]) -> Option<PathBuf> {
    if path.is_empty() {
        return None;
    }
    let base = path
        .iter()
        .fold(root().join("src"), |dir, part| dir.join(part));
    [base.with_extension("rs"), base.join("mod.rs")]
        .into_iter()
        .find(|f| f.is_file())
}

fn sources(dir: &Path, found: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            sources(&path, found);
        } else if path.extension().is_some_and(|e| e == "rs") {
            found.push(path);
        }
    }
}

/// Code lines of a file outside comments and outside inline `#[cfg(test)]` modules, and the
/// names of the modules it declares under `#[cfg(test)]` in files of their own.
fn production_code(text: &str) -> (Vec<String>, Vec<String>) {
    let (mut code, mut test_modules) = (Vec::new(), Vec::new());
    let mut lines = text.lines().peekable();
    while let Some(line) = lines.next() {
        let trimmed = line.trim_start();
        if trimmed.starts_with("//") {
            continue;
        }
        if trimmed.starts_with("#[cfg(test)]") {
            let next = lines.peek().map(|l| l.trim()).unwrap_or_default();
            let declared = next
                .trim_start_matches("pub(crate) ")
                .trim_start_matches("pub ")
                .strip_prefix("mod ");
            match declared {
                Some(rest) if rest.ends_with(';') => {
                    test_modules.push(rest.trim_end_matches(';').to_string());
                }
                // An inline test module runs to the end of the file in this code base.
                Some(_) => break,
                None => {}
            }
            continue;
        }
        code.push(line.split("//").next().unwrap_or_default().to_string());
    }
    (code, test_modules)
}

/// Paths (from the crate root) that `code` names, for a file at module path `here`.
fn named_paths(code: &[String], here: &[String]) -> Vec<Vec<String>> {
    let ident = |c: char| c.is_alphanumeric() || c == '_';
    let mut paths = Vec::new();
    let text = code.join("\n");
    // `super` is the parent of the file's module, `self` the module itself (a `mod.rs` file's
    // module path is already its folder's).
    let parent = here[..here.len().saturating_sub(1)].to_vec();
    for (prefix, base) in [
        ("crate::", Vec::new()),
        ("super::", parent),
        ("self::", here.to_vec()),
    ] {
        for (i, _) in text.match_indices(prefix) {
            if text[..i].ends_with(ident) || text[..i].ends_with("::") {
                continue;
            }
            let rest = &text[i + prefix.len()..];
            // `a::b::{c, d}` or `a::b::c`: every segment up to a brace or a non-path character.
            let mut path = base.clone();
            for segment in rest.split("::") {
                let name: String = segment.chars().take_while(|&c| ident(c)).collect();
                if name.is_empty() {
                    // A group `{a, b::c}`: each member's first segment.
                    if let Some(group) = segment.strip_prefix('{') {
                        let group = group.split('}').next().unwrap_or_default();
                        for member in group.split(',') {
                            let first: String =
                                member.trim().chars().take_while(|&c| ident(c)).collect();
                            if !first.is_empty() && first != "self" {
                                let mut p = path.clone();
                                p.push(first);
                                paths.push(p);
                            }
                        }
                    }
                    break;
                }
                let last = name.len() < segment.len();
                if name == "super" {
                    path.pop();
                    continue;
                }
                path.push(name);
                if last {
                    break;
                }
            }
            paths.push(path);
        }
    }
    paths
}

/// The file a path names: its longest prefix that is a module file.
fn resolve(path: &[String]) -> Option<PathBuf> {
    (1..=path.len()).rev().find_map(|n| file_of(&path[..n]))
}

struct Library {
    /// Production file -> the production files it imports.
    edges: BTreeMap<PathBuf, BTreeSet<PathBuf>>,
}

fn library() -> Library {
    let mut files = Vec::new();
    sources(&root().join("src"), &mut files);
    let mut test_only = BTreeSet::new();
    let mut code_of = BTreeMap::new();
    for file in &files {
        let text = std::fs::read_to_string(file).unwrap();
        let (code, test_modules) = production_code(&text);
        let dir = file.parent().unwrap();
        let own_dir = if file.file_name().unwrap() == "mod.rs"
            || file.file_name().unwrap() == "lib.rs"
            || file.file_name().unwrap() == "main.rs"
        {
            dir.to_path_buf()
        } else {
            dir.join(file.file_stem().unwrap())
        };
        for name in test_modules {
            test_only.insert(own_dir.join(format!("{name}.rs")));
            test_only.insert(own_dir.join(&name));
        }
        code_of.insert(file.clone(), code);
    }
    let is_test_only = |f: &Path| test_only.iter().any(|t| f.starts_with(t));
    let mut edges = BTreeMap::new();
    for (file, code) in &code_of {
        let name = file.file_name().unwrap();
        if is_test_only(file) || name == "lib.rs" || name == "main.rs" {
            continue;
        }
        let here = module_path(file);
        let targets: BTreeSet<PathBuf> = named_paths(code, &here)
            .iter()
            .filter_map(|p| resolve(p))
            .filter(|t| t != file && !is_test_only(t))
            .collect();
        edges.insert(file.clone(), targets);
    }
    Library { edges }
}

fn short(file: &Path) -> String {
    file.strip_prefix(root().join("src"))
        .unwrap()
        .to_string_lossy()
        .to_string()
}

#[test]
fn production_code_imports_only_from_lower_layers() {
    let layers = layers();
    let library = library();
    assert!(library.edges.len() > 100, "sources not found");
    let top = |file: &Path| module_path(file)[0].clone();
    let mut upward = Vec::new();
    for (file, targets) in &library.edges {
        let from = top(file);
        let from_layer = *layers
            .get(&from)
            .unwrap_or_else(|| panic!("module `{from}` is in no layer of docs/layout.md"));
        for target in targets {
            let to = top(target);
            if to == from {
                continue;
            }
            let to_layer = *layers
                .get(&to)
                .unwrap_or_else(|| panic!("module `{to}` is in no layer of docs/layout.md"));
            if to_layer >= from_layer {
                upward.push(format!(
                    "{} (layer {from_layer}) -> {} (layer {to_layer})",
                    short(file),
                    short(target)
                ));
            }
        }
    }
    assert!(
        upward.is_empty(),
        "imports that do not go down:\n{}",
        upward.join("\n")
    );
}

/// The circles of the import graph `edges`: each the files (named from `src/`, sorted) that
/// import each other, directly or around a circle; edges between a file and the files of its
/// ancestor modules do not count.
fn circles(edges: &BTreeMap<PathBuf, BTreeSet<PathBuf>>) -> Vec<Vec<String>> {
    // The files of a file's ancestor modules are its folder's interface, not a circle.
    let is_ancestor_interface = |file: &Path, target: &Path| {
        let (inner, outer) = (module_path(file), module_path(target));
        outer.len() < inner.len() && inner.starts_with(&outer)
    };
    let graph: BTreeMap<&PathBuf, Vec<&PathBuf>> = edges
        .iter()
        .map(|(f, ts)| {
            (
                f,
                ts.iter()
                    .filter(|t| !is_ancestor_interface(f, t) && !is_ancestor_interface(t, f))
                    .collect(),
            )
        })
        .collect();
    // Tarjan's strongly connected components (Tarjan 1972).
    struct State<'a> {
        index: BTreeMap<&'a PathBuf, usize>,
        low: BTreeMap<&'a PathBuf, usize>,
        stack: Vec<&'a PathBuf>,
        on_stack: BTreeSet<&'a PathBuf>,
        components: Vec<Vec<&'a PathBuf>>,
    }
    fn visit<'a>(
        v: &'a PathBuf,
        graph: &BTreeMap<&'a PathBuf, Vec<&'a PathBuf>>,
        s: &mut State<'a>,
    ) {
        let i = s.index.len();
        s.index.insert(v, i);
        s.low.insert(v, i);
        s.stack.push(v);
        s.on_stack.insert(v);
        for &w in graph.get(v).into_iter().flatten() {
            if !s.index.contains_key(w) {
                visit(w, graph, s);
                let low = s.low[v].min(s.low[w]);
                s.low.insert(v, low);
            } else if s.on_stack.contains(w) {
                let low = s.low[v].min(s.index[w]);
                s.low.insert(v, low);
            }
        }
        if s.low[v] == s.index[v] {
            let mut component = Vec::new();
            while let Some(w) = s.stack.pop() {
                s.on_stack.remove(w);
                component.push(w);
                if w == v {
                    break;
                }
            }
            if component.len() > 1 {
                s.components.push(component);
            }
        }
    }
    let mut state = State {
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on_stack: BTreeSet::new(),
        components: Vec::new(),
    };
    for &v in graph.keys() {
        if !state.index.contains_key(v) {
            visit(v, &graph, &mut state);
        }
    }
    let mut circles: Vec<Vec<String>> = state
        .components
        .iter()
        .map(|c| {
            let mut names: Vec<String> = c.iter().map(|f| short(f)).collect();
            names.sort();
            names
        })
        .collect();
    circles.sort();
    circles
}

#[test]
fn the_circle_search_finds_every_circle_and_no_other() {
    let file = |name: &str| root().join("src").join(name);
    let edges: BTreeMap<PathBuf, BTreeSet<PathBuf>> = [
        // Two files that import each other, and three around a circle.
        ("a.rs", &["b.rs"][..]),
        ("b.rs", &["a.rs"]),
        ("x.rs", &["y.rs"]),
        ("y.rs", &["z/mod.rs"]),
        ("z/mod.rs", &["x.rs", "z/inner.rs"]),
        // A file and its folder's interface import each other (no circle); a file that only
        // imports.
        ("z/inner.rs", &["z/mod.rs", "a.rs"]),
        ("top.rs", &["x.rs", "z/inner.rs"]),
    ]
    .into_iter()
    .map(|(from, to)| (file(from), to.iter().map(|t| file(t)).collect()))
    .collect();
    assert_eq!(
        circles(&edges),
        [vec!["a.rs", "b.rs"], vec!["x.rs", "y.rs", "z/mod.rs"]]
    );
}

#[test]
fn no_two_files_import_each_other_around_a_circle() {
    let mut circles = circles(&library().edges);
    // Each known circle is still found (so the search works; when one is broken, take it off
    // KNOWN_CIRCLES so that it cannot come back), and no other.
    for known in KNOWN_CIRCLES {
        let known: Vec<String> = known.iter().map(|s| s.to_string()).collect();
        let found = circles.iter().position(|c| *c == known);
        assert!(
            found.is_some(),
            "{known:?} no longer import each other: take them off KNOWN_CIRCLES"
        );
        circles.remove(found.unwrap());
    }
    assert!(
        circles.is_empty(),
        "files that import each other: {circles:?}"
    );
}

#[test]
fn the_point_room_never_calls_into_the_bayes_room() {
    // docs/layout.md: inside `fit/`, calls go only from `bayes/` into `point/`.
    let library = library();
    let (point, bayes) = (root().join("src/fit/point"), root().join("src/fit/bayes"));
    let files: Vec<&PathBuf> = library
        .edges
        .keys()
        .filter(|f| f.starts_with(&point))
        .collect();
    assert!(files.len() >= 8, "point/ sources not found");
    for file in files {
        for target in &library.edges[file] {
            assert!(
                !target.starts_with(&bayes),
                "the point room calls into bayes: {} -> {}",
                short(file),
                short(target)
            );
        }
    }
}
